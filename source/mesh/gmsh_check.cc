// SPDX-License-Identifier: LGPL-2.1-or-later
// Structural check of a Gmsh ASCII file. The rules follow what deal.II 9.4's
// GridIn<3>::read_msh(std::istream &) reads (source/grid/grid_in.cc): it reads token by token
// with operator>> and never checks the stream inside its loops, so a wrong count makes it read
// on a failed stream; it sizes `vertices` by the node count of the header, writes one vertex per
// node of the blocks into it, and keeps node tags in a std::map<int, int>.
#include <shard/mesh/gmsh_check.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ios>
#include <iterator>
#include <limits>
#include <string_view>
#include <utility>
#include <vector>

namespace shard::mesh
{
  namespace
  {
    /// Longest line read: Gmsh lines are short; this bounds memory on an endless stream.
    constexpr std::size_t max_line_length = std::size_t(8) << 20;
    /// deal.II reads tags and counts into int or unsigned int.
    constexpr long long max_int = std::numeric_limits<int>::max();
    /// Largest boundary id (numbers::internal_face_boundary_id - 1).
    constexpr long long max_boundary_id = 254;

    /// A quoted excerpt of the file: at most 40 characters, bytes outside 0x20-0x7e as \xHH.
    std::string
    quote(const std::string_view text)
    {
      std::string out = "'";
      std::size_t length = 0;
      for (const char ch : text)
        {
          const auto c = static_cast<unsigned char>(ch);
          char       piece[8] = {ch, 0};
          if (c < 0x20 || c > 0x7e)
            std::snprintf(piece, sizeof(piece), "\\x%02x", c);
          const std::size_t n = std::strlen(piece);
          if (length + n > 40)
            {
              out += "...";
              break;
            }
          out += piece;
          length += n;
        }
      return out + "'";
    }

    template <typename Integer>
    std::string
    str(const Integer n)
    {
      return std::to_string(n);
    }

    bool
    is_text(const unsigned char c)
    {
      return (c >= 0x20 && c != 0x7f) || c == '\t' || c == '\r' || c == '\n';
    }

    /// Reads a stream line by line in chunks, checks every byte and the line length.
    class LineReader
    {
    public:
      explicit LineReader(std::istream &in)
        : in_(in)
        , buffer_(1 << 16)
      {}

      /// The next line without its end; false at the end of the stream.
      bool
      next(std::string &line)
      {
        line.clear();
        bool any = false;
        for (;;)
          {
            if (pos_ == end_ && !fill())
              {
                if (!any)
                  return false;
                ++number_;
                return true;
              }
            any             = true;
            const char *b   = buffer_.data() + pos_;
            const auto  n   = end_ - pos_;
            const auto *nl  = static_cast<const char *>(std::memchr(b, '\n', n));
            const auto  len = nl ? static_cast<std::size_t>(nl - b) : n;
            for (std::size_t i = 0; i < len; ++i)
              if (!is_text(static_cast<unsigned char>(b[i])))
                {
                  char code[8];
                  std::snprintf(code, sizeof(code), "\\x%02x", static_cast<unsigned char>(b[i]));
                  throw GmshError(number_ + 1, std::string("a byte that is not text (") + code + ") at column " +
                                                 str(line.size() + i + 1) +
                                                 ": shard reads ASCII Gmsh files only");
                }
            if (line.size() + len > max_line_length)
              throw GmshError(number_ + 1,
                              "a line longer than " + str(max_line_length) + " characters: not a Gmsh ASCII file");
            line.append(b, len);
            pos_ += len;
            if (nl)
              {
                ++pos_;
                ++number_;
                return true;
              }
          }
      }

      /// Number of the last line returned by next() (0 before the first).
      unsigned long long
      number() const
      {
        return number_;
      }

    private:
      bool
      fill()
      {
        if (done_)
          return false;
        try
          {
            in_.read(buffer_.data(), static_cast<std::streamsize>(buffer_.size()));
          }
        catch (const std::ios_base::failure &)
          {
            // The caller's exception mask: the state bits below tell what happened.
          }
        if (in_.bad())
          throw GmshError(number_ + 1, "the file cannot be read (is it a directory?)");
        pos_ = 0;
        end_ = static_cast<std::size_t>(in_.gcount());
        if (end_ < buffer_.size())
          done_ = true;
        return end_ > 0;
      }

      std::istream      &in_;
      std::vector<char>  buffer_;
      std::size_t        pos_    = 0;
      std::size_t        end_    = 0;
      unsigned long long number_ = 0;
      bool               done_   = false;
    };

    /// Gmsh element types: number of nodes, dimension and name (0 nodes: unknown type).
    struct ElementType
    {
      unsigned int n_nodes;
      int          dim;
      const char  *name;
    };

    ElementType
    element_type(const long long type)
    {
      static const ElementType types[] = {
        {0, 0, ""},
        {2, 1, "line"},
        {3, 2, "triangle"},
        {4, 2, "quadrilateral"},
        {4, 3, "tetrahedron"},
        {8, 3, "hexahedron"},
        {6, 3, "prism"},
        {5, 3, "pyramid"},
        {3, 1, "3-node second-order line"},
        {6, 2, "6-node second-order triangle"},
        {9, 2, "9-node second-order quadrilateral"},
        {10, 3, "10-node second-order tetrahedron"},
        {27, 3, "27-node second-order hexahedron"},
        {18, 3, "18-node second-order prism"},
        {14, 3, "14-node second-order pyramid"},
        {1, 0, "point"},
        {8, 2, "8-node second-order quadrilateral"},
        {20, 3, "20-node second-order hexahedron"},
        {15, 3, "15-node second-order prism"},
        {13, 3, "13-node second-order pyramid"},
      };
      if (type >= 1 && type < static_cast<long long>(sizeof(types) / sizeof(types[0])))
        return types[type];
      return types[0];
    }

    /// Element type @p type with its name, e.g. "type 5 (hexahedron)".
    std::string
    type_name(const long long type)
    {
      const auto t = element_type(type);
      return "type " + str(type) + (t.n_nodes ? std::string(" (") + t.name + ")" : std::string());
    }

    /// Parses an integer (an optional '+' or '-' then digits only).
    bool
    to_integer(std::string_view s, long long &value)
    {
      if (s.size() > 1 && s[0] == '+' && s[1] != '-')
        s.remove_prefix(1);
      const auto r = std::from_chars(s.data(), s.data() + s.size(), value);
      return r.ec == std::errc() && r.ptr == s.data() + s.size();
    }

    enum class Real
    {
      ok,
      not_a_number,
      not_finite
    };

    /// Parses a number as operator>> reads it; an underflow reads as a tiny number or 0, as there.
    Real
    to_real(std::string_view s, double &value)
    {
      if (s.size() > 1 && s[0] == '+' && s[1] != '-')
        s.remove_prefix(1);
      const auto r = std::from_chars(s.data(), s.data() + s.size(), value, std::chars_format::general);
      if (s.empty() || r.ptr != s.data() + s.size())
        return Real::not_a_number;
      if (r.ec == std::errc::result_out_of_range)
        {
          const std::string copy(s);
          value = std::strtod(copy.c_str(), nullptr);
          return std::isfinite(value) ? Real::ok : Real::not_finite;
        }
      if (r.ec != std::errc())
        return Real::not_a_number;
      return std::isfinite(value) ? Real::ok : Real::not_finite;
    }

    /// One node of `$Nodes`: its tag and line.
    struct NodeRecord
    {
      std::int32_t       tag;
      unsigned long long line;
    };

    class Scanner
    {
    public:
      explicit Scanner(std::istream &in)
        : lines_(in)
      {}

      GmshSummary
      run();

    private:
      [[noreturn]] void
      fail(const std::string &problem) const
      {
        throw GmshError(lines_.number(), problem);
      }

      [[noreturn]] static void
      fail(const unsigned long long line, const std::string &problem)
      {
        throw GmshError(line, problem);
      }

      /// Reads the next line that is not blank into line_ and fields_; false at the end.
      bool
      next_line()
      {
        while (lines_.next(line_))
          {
            split();
            if (!fields_.empty())
              return true;
          }
        return false;
      }

      void
      split()
      {
        fields_.clear();
        const std::string_view s(line_);
        std::size_t            i = 0;
        const auto             space = [](const char c) { return c == ' ' || c == '\t' || c == '\r'; };
        while (i < s.size())
          {
            while (i < s.size() && space(s[i]))
              ++i;
            const auto b = i;
            while (i < s.size() && !space(s[i]))
              ++i;
            if (i > b)
              fields_.push_back(s.substr(b, i - b));
          }
      }

      /// The current line without surrounding blanks.
      std::string_view
      trimmed() const
      {
        return fields_.empty() ? std::string_view() :
                                 std::string_view(fields_.front().data(),
                                                  fields_.back().data() + fields_.back().size() -
                                                    fields_.front().data());
      }

      /// True if the current line is the section marker @p marker alone.
      bool
      is(const std::string_view marker) const
      {
        return fields_.size() == 1 && fields_[0] == marker;
      }

      /**
       * Reads the next data line of @p section (begun at line @p start): fails at the end of the
       * file or at a line starting with '$'. @p item, @p index and @p count describe what was
       * expected, e.g. "node line", 16, 459.
       */
      void
      data_line(const std::string_view section, const unsigned long long start, const char *item,
                const unsigned long long index, const unsigned long long count)
      {
        if (!next_line())
          fail(start, "$" + std::string(section) + " is not ended by $End" + std::string(section) +
                        ": the file ends at line " + str(lines_.number()) + ", at " + item + " " + str(index) +
                        " of " + str(count));
        if (fields_[0][0] == '$')
          fail(quote(trimmed()) + " where " + item + " " + str(index) + " of " + str(count) +
               " was expected (the count is at line " + str(count_line_) + ")");
      }

      /// Reads the end marker of @p section after its data.
      void
      end_marker(const std::string_view section, const unsigned long long start, const std::string &after)
      {
        const std::string end = "$End" + std::string(section);
        if (!next_line())
          fail(start, "$" + std::string(section) + " is not ended by " + end + ": the file ends at line " +
                        str(lines_.number()));
        if (!is(end))
          fail("expected " + end + " after " + after + "; found " + quote(trimmed()));
      }

      /// Fails unless the current line has @p n fields.
      void
      expect_fields(const std::size_t n, const std::string &form)
      {
        if (fields_.size() != n)
          fail(form + "; found " + str(fields_.size()));
      }

      /// Field @p i as an integer in [@p lo, @p hi]; @p what names it.
      long long
      integer(const std::size_t i, const char *what, const long long lo = 0, const long long hi = max_int)
      {
        long long v = 0;
        if (!to_integer(fields_[i], v) || v < lo || v > hi)
          fail(std::string("the ") + what + " " + quote(fields_[i]) + " is not an integer in " + str(lo) + ".." +
               str(hi));
        return v;
      }

      /// Field @p i as a finite number.
      void
      real(const std::size_t i, const char *what)
      {
        double     v = 0;
        const auto r = to_real(fields_[i], v);
        if (r == Real::not_a_number)
          fail(std::string("the ") + what + " " + quote(fields_[i]) + " is not a number");
        if (r == Real::not_finite)
          fail(std::string("the ") + what + " " + quote(fields_[i]) + " is not a finite number");
      }

      void
      mesh_format();
      void
      skip_section(const std::string &name, unsigned long long start);
      void
      entities(unsigned long long start);
      void
      nodes(unsigned long long start);
      void
      nodes_2(unsigned long long start);
      /// The header line `blocks count smallest-tag largest-tag` of a version 4.1 $Nodes or
      /// $Elements section (@p noun "node" or "element"); sets count_line_ to it.
      struct Header41
      {
        long long n_blocks = 0, n = 0, min_tag = 0, max_tag = 0;
      };
      Header41
      header_41(unsigned long long start, const std::string &section, const std::string &noun);
      void
      nodes_41(unsigned long long start);
      void
      add_node(long long tag);
      void
      finish_nodes();
      void
      elements(unsigned long long start);
      void
      elements_2(unsigned long long start);
      void
      elements_41(unsigned long long start);
      void
      check_element(long long tag, long long type, std::size_t first_node, bool has_physical, long long physical);
      bool
      node_exists(long long tag) const;

      LineReader                    lines_;
      std::string                   line_;
      std::vector<std::string_view> fields_;
      bool                          v41_ = false;
      GmshSummary                   summary_;
      unsigned long long            count_line_ = 0;
      std::vector<NodeRecord>       nodes_;
      std::vector<std::int32_t>     tags_;
      bool                          contiguous_ = false;
    };

    GmshSummary
    Scanner::run()
    {
      if (!next_line())
        fail(1, "the file is empty: a Gmsh file starts with $MeshFormat");
      if (!is("$MeshFormat"))
        fail("a Gmsh file starts with $MeshFormat; found " + quote(trimmed()) +
             (is("$NOD") ? " (Gmsh format 1, which shard does not read)" : ""));
      mesh_format();

      // deal.II reads, in this order: [$PhysicalNames] [$Entities] [$PartitionedEntities] $Nodes
      // $Elements, and nothing after $EndElements.
      unsigned long long nodes_at = 0, elements_at = 0, last_rank = 0;
      const char        *before_nodes = v41_ ? "$PhysicalNames, $Entities and $PartitionedEntities, in this order" :
                                               "$PhysicalNames";
      while (next_line())
        {
          const auto start = lines_.number();
          if (fields_.size() != 1 || fields_[0][0] != '$' || fields_[0].size() < 2)
            fail("expected a section such as $Nodes or $Elements; found " + quote(trimmed()));
          const std::string name(fields_[0].substr(1));
          if (name.compare(0, 3, "End") == 0)
            fail(quote(trimmed()) + " ends no open section");
          if (name == "MeshFormat")
            fail("a second $MeshFormat section (the first is at line 1)");
          if (name == "Nodes")
            {
              if (nodes_at)
                fail("a second $Nodes section (the first is at line " + str(nodes_at) + ")");
              nodes_at = start;
              nodes(start);
              if (!next_line())
                fail(lines_.number(), "no $Elements section: the file ends after $EndNodes");
              if (!is("$Elements"))
                fail("$Elements must follow $EndNodes (deal.II reads them in sequence); found " + quote(trimmed()));
              elements_at = lines_.number();
              elements(elements_at);
              continue;
            }
          if (name == "Elements")
            fail(elements_at ? "a second $Elements section (the first is at line " + str(elements_at) + ")" :
                               std::string("$Elements before $Nodes"));
          if (!nodes_at)
            {
              const unsigned long long rank = name == "PhysicalNames"           ? 1 :
                                              name == "Entities" && v41_        ? 2 :
                                              name == "PartitionedEntities" && v41_ ? 3 : 0;
              if (rank == 0 || rank <= last_rank)
                fail(quote(trimmed()) + " before $Nodes: deal.II 9.4 reads only " + before_nodes +
                     " between $EndMeshFormat and $Nodes");
              last_rank = rank;
              if (rank == 2)
                {
                  entities(start);
                  continue;
                }
            }
          skip_section(name, start);
        }
      if (!nodes_at)
        fail(lines_.number(), "no $Nodes section (the file ends at line " + str(lines_.number()) + ")");
      if (summary_.n_hexahedra == 0)
        fail(elements_at, "no hexahedra (gmsh type 5): shard meshes bodies with hexahedra only");
      return summary_;
    }

    void
    Scanner::mesh_format()
    {
      const auto start = lines_.number();
      if (!next_line())
        fail(start, "$MeshFormat is not ended by $EndMeshFormat: the file ends at line " + str(lines_.number()));
      expect_fields(3, "the $MeshFormat line has 3 numbers (version file-type data-size, e.g. '4.1 0 8')");
      double version = 0;
      if (to_real(fields_[0], version) != Real::ok)
        fail("the version " + quote(fields_[0]) + " is not a number");
      const double supported[] = {2.0, 2.1, 2.2, 4.1};
      if (std::none_of(std::begin(supported), std::end(supported),
                       [&](const double v) { return std::abs(version - v) < 1e-9; }))
        fail("Gmsh format version " + quote(fields_[0]) +
             " is not supported: shard reads ASCII versions 2.2 and 4.1 (and 2.0, 2.1); "
             "save with gmsh -format msh41 (or msh22)");
      long long file_type = 0;
      if (!to_integer(fields_[1], file_type) || (file_type != 0 && file_type != 1))
        fail("the file-type " + quote(fields_[1]) + " is not 0 (ASCII) or 1 (binary)");
      if (file_type == 1)
        fail("binary Gmsh files are not supported (file-type 1): save as ASCII "
             "(gmsh without -bin, or Mesh.Binary = 0)");
      long long data_size = 0;
      if (!to_integer(fields_[2], data_size) || data_size != 8)
        fail("the data-size " + quote(fields_[2]) + " is not 8 (the size of a double)");
      v41_             = version > 3;
      summary_.version = version;
      if (!next_line())
        fail(start, "$MeshFormat is not ended by $EndMeshFormat: the file ends at line " + str(lines_.number()));
      if (!is("$EndMeshFormat"))
        fail("expected $EndMeshFormat after the version line; found " + quote(trimmed()));
    }

    void
    Scanner::skip_section(const std::string &name, const unsigned long long start)
    {
      const std::string end = "$End" + name;
      while (next_line())
        if (is(end))
          return;
      fail(start, "$" + name + " is not ended by " + end + " (the file ends at line " + str(lines_.number()) + ")");
    }

    void
    Scanner::entities(const unsigned long long start)
    {
      if (!next_line() || fields_[0][0] == '$')
        fail(start, "$Entities has no header line (points curves surfaces volumes)");
      expect_fields(4, "the $Entities header has 4 numbers (points, curves, surfaces, volumes)");
      count_line_ = lines_.number();
      long long n[4];
      for (unsigned int d = 0; d < 4; ++d)
        n[d] = integer(d, "entity count");
      static const char *kind[4] = {"point", "curve", "surface", "volume"};
      static const char *item[4] = {"point entity", "curve entity", "surface entity", "volume entity"};
      unsigned long long total = 0;
      for (unsigned int d = 0; d < 4; ++d)
        for (long long k = 0; k < n[d]; ++k)
          {
            data_line("Entities", start, item[d], static_cast<unsigned long long>(k + 1),
                      static_cast<unsigned long long>(n[d]));
            ++total;
            // point: tag x y z nphys phys...; others: tag 6 box numbers nphys phys... nbound bound...
            const std::size_t n_box = d == 0 ? 3 : 6;
            const std::string form = std::string("a ") + kind[d] + " entity line is 'tag " +
                                     (d == 0 ? "x y z" : "minx miny minz maxx maxy maxz") + " n-physical physical..." +
                                     (d == 0 ? "" : " n-bounding bounding...") + "'";
            if (fields_.size() < n_box + 2 + (d > 0))
              fail(form + "; found " + str(fields_.size()) + " numbers");
            const long long tag = integer(0, "entity tag", -max_int, max_int);
            for (std::size_t i = 1; i <= n_box; ++i)
              real(i, "coordinate");
            const long long n_physical = integer(n_box + 1, "number of physical tags");
            if (n_physical > 1)
              fail(std::string(kind[d]) + " " + str(tag) + " belongs to " + str(n_physical) +
                   " physical groups: deal.II 9.4 reads at most one per entity");
            const std::size_t after = n_box + 2 + static_cast<std::size_t>(n_physical);
            if (fields_.size() < after + (d > 0))
              fail(form + "; found " + str(fields_.size()) + " numbers");
            if (n_physical == 1)
              {
                const long long physical = integer(n_box + 2, "physical tag", -max_int, max_int);
                if ((d == 1 || d == 2) && (physical < 0 || physical > max_boundary_id))
                  fail("the physical tag " + str(physical) + " of " + kind[d] + " " + str(tag) +
                       " becomes a boundary id, which must be 0.." + str(max_boundary_id));
              }
            std::size_t expected = after;
            if (d > 0)
              {
                const long long n_bounding = integer(after, "number of bounding entities");
                expected                   = after + 1 + static_cast<std::size_t>(n_bounding);
                if (fields_.size() == expected)
                  for (std::size_t i = after + 1; i < expected; ++i)
                    integer(i, "bounding entity tag", -max_int, max_int);
              }
            if (fields_.size() != expected)
              fail(form + ": " + str(expected) + " numbers here; found " +
                   str(fields_.size()));
          }
      end_marker("Entities", start, str(total) + " entities (the header is at line " + str(count_line_) + ")");
    }

    void
    Scanner::nodes(const unsigned long long start)
    {
      if (v41_)
        nodes_41(start);
      else
        nodes_2(start);
      finish_nodes();
    }

    void
    Scanner::add_node(const long long tag)
    {
      nodes_.push_back({static_cast<std::int32_t>(tag), lines_.number()});
    }

    void
    Scanner::nodes_2(const unsigned long long start)
    {
      if (!next_line() || fields_[0][0] == '$')
        fail(start, "$Nodes has no count line");
      count_line_ = lines_.number();
      if (fields_.size() != 1)
        fail("the $Nodes header of a version 2.2 file has 1 number (the node count); found " +
             str(fields_.size()) +
             (fields_.size() == 4 ? ": is this a version 4.1 file with a 2.2 header?" : ""));
      const auto n = static_cast<unsigned long long>(integer(0, "node count"));
      for (unsigned long long k = 0; k < n; ++k)
        {
          data_line("Nodes", start, "node line", k + 1, n);
          expect_fields(4, "a node line of a version 2.2 file has 4 numbers (tag x y z)");
          const long long tag = integer(0, "node tag", 1);
          for (std::size_t i = 1; i < 4; ++i)
            real(i, "coordinate");
          add_node(tag);
        }
      summary_.n_nodes = n;
      end_marker("Nodes", start, str(n) + " node lines (the count is at line " + str(count_line_) + ")");
    }

    Scanner::Header41
    Scanner::header_41(const unsigned long long start, const std::string &section, const std::string &noun)
    {
      const std::string nouns = noun + "s";
      if (!next_line() || fields_[0][0] == '$')
        fail(start, "$" + section + " has no header line (blocks " + nouns + " smallest-tag largest-tag)");
      count_line_ = lines_.number();
      if (fields_.size() != 4)
        fail("the $" + section + " header of a version 4.1 file has 4 numbers (blocks, " + nouns +
             ", smallest tag, largest tag); found " + str(fields_.size()) +
             (fields_.size() == 1 ? ": is this a version 2.2 file with a 4.1 header?" : ""));
      const std::string blocks = "number of " + noun + " blocks", count = noun + " count",
                        smallest = "smallest " + noun + " tag", largest = "largest " + noun + " tag";
      Header41 h;
      h.n_blocks = integer(0, blocks.c_str());
      h.n        = integer(1, count.c_str());
      h.min_tag  = integer(2, smallest.c_str(), h.n ? 1 : 0);
      h.max_tag  = integer(3, largest.c_str(), h.n ? 1 : 0);
      if (h.n > 0 && (h.max_tag < h.min_tag || h.max_tag - h.min_tag + 1 < h.n))
        fail("the $" + section + " header declares " + str(h.n) + " " + nouns + " with tags " + str(h.min_tag) +
             ".." + str(h.max_tag) + ": too few tags for distinct " + nouns);
      return h;
    }

    void
    Scanner::nodes_41(const unsigned long long start)
    {
      const auto [n_blocks, n_nodes, min_tag, max_tag] = header_41(start, "Nodes", "node");
      const unsigned long long header                  = count_line_;
      long long                total  = 0;
      for (long long b = 0; b < n_blocks; ++b)
        {
          count_line_ = header;
          data_line("Nodes", start, "node block", static_cast<unsigned long long>(b + 1),
                    static_cast<unsigned long long>(n_blocks));
          const auto block_line = lines_.number();
          expect_fields(4, "a node block header of a version 4.1 file has 4 numbers (entity dimension, entity tag, "
                           "parametric, nodes in block)");
          const long long dim        = integer(0, "entity dimension", 0, 3);
          integer(1, "entity tag", -max_int, max_int);
          const long long parametric = integer(2, "parametric flag", 0, 1);
          const long long n          = integer(3, "number of nodes in the block");
          if (parametric && dim != 2)
            fail("parametric node coordinates on an entity of dimension " + str(dim) +
                 ": deal.II 9.4 reads them only on surfaces; save with Mesh.SaveParametric = 0");
          if (n > n_nodes - total)
            fail("the node blocks hold more than the " + str(n_nodes) + " nodes of the $Nodes header (line " +
                 str(header) + ")");
          total += n;
          count_line_ = block_line;
          for (long long k = 0; k < n; ++k)
            {
              data_line("Nodes", start, "node tag line", static_cast<unsigned long long>(k + 1),
                        static_cast<unsigned long long>(n));
              expect_fields(1, "a node tag line of a version 4.1 file has 1 number (the tag)");
              long long tag = 0;
              if (!to_integer(fields_[0], tag) || tag < min_tag || tag > max_tag)
                fail("the node tag " + quote(fields_[0]) + " is not an integer in the range " + str(min_tag) + ".." +
                     str(max_tag) + " of the $Nodes header (line " + str(header) + ")");
              add_node(tag);
            }
          const std::size_t n_coordinates = parametric ? 5 : 3;
          for (long long k = 0; k < n; ++k)
            {
              data_line("Nodes", start, "node coordinate line", static_cast<unsigned long long>(k + 1),
                        static_cast<unsigned long long>(n));
              expect_fields(n_coordinates, parametric ? "a node coordinate line of a parametric block has 5 numbers "
                                                        "(x y z u v)" :
                                                        "a node coordinate line has 3 numbers (x y z)");
              for (std::size_t i = 0; i < n_coordinates; ++i)
                real(i, "coordinate");
            }
        }
      if (total != n_nodes)
        {
          if (!next_line())
            fail(start, "$Nodes is not ended by $EndNodes: the file ends at line " + str(lines_.number()));
          fail("the " + str(n_blocks) + " node blocks hold " + str(total) + " nodes; the $Nodes header (line " +
               str(header) + ") declares " + str(n_nodes));
        }
      summary_.n_nodes = static_cast<unsigned long long>(n_nodes);
      end_marker("Nodes", start, str(n_blocks) + " node blocks (the header is at line " + str(header) + ")");
    }

    void
    Scanner::finish_nodes()
    {
      std::sort(nodes_.begin(), nodes_.end(), [](const NodeRecord &a, const NodeRecord &b) {
        return a.tag < b.tag || (a.tag == b.tag && a.line < b.line);
      });
      for (std::size_t i = 1; i < nodes_.size(); ++i)
        if (nodes_[i].tag == nodes_[i - 1].tag)
          fail(nodes_[i].line, "node tag " + str(nodes_[i].tag) +
                                 " appears twice (also at line " + str(nodes_[i - 1].line) + ")");
      tags_.reserve(nodes_.size());
      for (const auto &n : nodes_)
        tags_.push_back(n.tag);
      std::vector<NodeRecord>().swap(nodes_);
      contiguous_ = tags_.empty() ||
                    static_cast<long long>(tags_.back()) - tags_.front() + 1 == static_cast<long long>(tags_.size());
    }

    bool
    Scanner::node_exists(const long long tag) const
    {
      if (tags_.empty() || tag < tags_.front() || tag > tags_.back())
        return false;
      return contiguous_ || std::binary_search(tags_.begin(), tags_.end(), static_cast<std::int32_t>(tag));
    }

    void
    Scanner::elements(const unsigned long long start)
    {
      if (v41_)
        elements_41(start);
      else
        elements_2(start);
    }

    /// Checks the type, the nodes from field @p first_node on and the physical tag of one element.
    void
    Scanner::check_element(const long long tag, const long long type, const std::size_t first_node,
                           const bool has_physical, const long long physical)
    {
      if (type == 1 || type == 3)
        {
          if (has_physical && (physical < 0 || physical > max_boundary_id))
            fail("the physical tag " + str(physical) + " of element " + str(tag) + " (a " + element_type(type).name +
                 ") becomes a boundary id, which must be 0.." + str(max_boundary_id));
        }
      else if (type == 5)
        ++summary_.n_hexahedra;
      for (std::size_t i = first_node; i < fields_.size(); ++i)
        {
          long long node = 0;
          if (!to_integer(fields_[i], node) || !node_exists(node))
            fail("element " + str(tag) + " refers to node " + quote(fields_[i]) + ", which is not in $Nodes");
        }
    }

    /// Fails for element types that are not hexahedra or their boundary (lines, quadrilaterals, points).
    void
    check_type(const long long type, const unsigned long long line)
    {
      if (type == 1 || type == 3 || type == 5 || type == 15)
        return;
      const auto t = element_type(type);
      if (type == 2 || type == 4 || type == 6 || type == 7)
        throw GmshError(line, "element " + type_name(type) +
                                ": shard meshes bodies with hexahedra only (gmsh type 5, bounded by "
                                "quadrilaterals, type 3)");
      if (t.n_nodes)
        throw GmshError(line, "element " + type_name(type) +
                                " is not supported: shard reads first-order hexahedra; save with "
                                "Mesh.ElementOrder = 1");
      throw GmshError(line, "element type " + str(type) +
                              " is not supported: shard reads hexahedra (gmsh type 5) and, on their boundary, lines, "
                              "quadrilaterals and points (types 1, 3, 15)");
    }

    void
    Scanner::elements_2(const unsigned long long start)
    {
      if (!next_line() || fields_[0][0] == '$')
        fail(start, "$Elements has no count line");
      count_line_ = lines_.number();
      if (fields_.size() != 1)
        fail("the $Elements header of a version 2.2 file has 1 number (the element count); found " +
             str(fields_.size()) +
             (fields_.size() == 4 ? ": is this a version 4.1 file with a 2.2 header?" : ""));
      const auto n = static_cast<unsigned long long>(integer(0, "element count"));
      for (unsigned long long k = 0; k < n; ++k)
        {
          data_line("Elements", start, "element line", k + 1, n);
          const char *form = "an element line of a version 2.2 file is 'tag type n-tags tag... node...'";
          if (fields_.size() < 3)
            fail(std::string(form) + "; found " + str(fields_.size()) + " numbers");
          const long long tag  = integer(0, "element tag", 1);
          const long long type = integer(1, "element type", 0);
          check_type(type, lines_.number());
          const long long n_tags = integer(2, "number of tags");
          const auto      t      = element_type(type);
          const auto      expect = 3 + static_cast<unsigned long long>(n_tags) + t.n_nodes;
          if (fields_.size() != expect)
            fail("an element of " + type_name(type) + " with " + str(n_tags) + " tags has " + str(expect) +
                 " numbers (tag type n-tags, " + str(n_tags) + " tags, " + str(t.n_nodes) + " nodes); found " +
                 str(fields_.size()));
          long long physical = 0;
          for (std::size_t i = 3; i < 3 + static_cast<std::size_t>(n_tags); ++i)
            {
              const long long v = integer(i, "tag", -max_int, max_int);
              if (i == 3)
                physical = v;
            }
          check_element(tag, type, 3 + static_cast<std::size_t>(n_tags), n_tags > 0, physical);
        }
      summary_.n_elements = n;
      end_marker("Elements", start, str(n) + " element lines (the count is at line " + str(count_line_) + ")");
    }

    void
    Scanner::elements_41(const unsigned long long start)
    {
      const auto [n_blocks, n_elements, min_tag, max_tag] = header_41(start, "Elements", "element");
      const unsigned long long header                     = count_line_;
      long long                total  = 0;
      for (long long b = 0; b < n_blocks; ++b)
        {
          count_line_ = header;
          data_line("Elements", start, "element block", static_cast<unsigned long long>(b + 1),
                    static_cast<unsigned long long>(n_blocks));
          const auto block_line = lines_.number();
          expect_fields(4, "an element block header of a version 4.1 file has 4 numbers (entity dimension, entity "
                           "tag, element type, elements in block)");
          const long long dim  = integer(0, "entity dimension", 0, 3);
          integer(1, "entity tag", -max_int, max_int);
          const long long type = integer(2, "element type", 0);
          const long long n    = integer(3, "number of elements in the block");
          check_type(type, block_line);
          const auto t = element_type(type);
          if (t.dim != dim)
            fail("an element block of " + type_name(type) + ", dimension " + str(t.dim) +
                 ", on an entity of dimension " + str(dim));
          if (n > n_elements - total)
            fail("the element blocks hold more than the " + str(n_elements) + " elements of the $Elements header "
                 "(line " + str(header) + ")");
          total += n;
          count_line_ = block_line;
          const std::string form = "an element line of " + type_name(type) + " has " + str(1ULL + t.n_nodes) +
                                   " numbers (tag and " + str(t.n_nodes) + " nodes)";
          for (long long k = 0; k < n; ++k)
            {
              data_line("Elements", start, "element line", static_cast<unsigned long long>(k + 1),
                        static_cast<unsigned long long>(n));
              expect_fields(1 + t.n_nodes, form);
              long long tag = 0;
              if (!to_integer(fields_[0], tag) || tag < min_tag || tag > max_tag)
                fail("the element tag " + quote(fields_[0]) + " is not an integer in the range " + str(min_tag) + ".." +
                     str(max_tag) + " of the $Elements header (line " + str(header) + ")");
              check_element(tag, type, 1, false, 0);
            }
        }
      if (total != n_elements)
        {
          if (!next_line())
            fail(start, "$Elements is not ended by $EndElements: the file ends at line " + str(lines_.number()));
          fail("the " + str(n_blocks) + " element blocks hold " + str(total) +
               " elements; the $Elements header (line " + str(header) + ") declares " + str(n_elements));
        }
      summary_.n_elements = static_cast<unsigned long long>(n_elements);
      end_marker("Elements", start, str(n_blocks) + " element blocks (the header is at line " + str(header) + ")");
    }
  } // namespace

  GmshError::GmshError(const unsigned long long line, const std::string &problem)
    : std::invalid_argument("line " + std::to_string(line) + ": " + problem)
    , line_(line)
  {}

  std::string
  GmshError::problem() const
  {
    const std::string what = this->what();
    const auto        at   = what.find(": ");
    return at == std::string::npos ? what : what.substr(at + 2);
  }

  GmshSummary
  check_gmsh(std::istream &in)
  {
    if (!in || in.rdbuf() == nullptr)
      throw GmshError(1, "the file cannot be read (is it missing, unreadable or a directory?)");
    Scanner scanner(in);
    return scanner.run();
  }
} // namespace shard::mesh
