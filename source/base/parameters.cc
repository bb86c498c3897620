// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/base/parameters.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <regex>
#include <set>
#include <stdexcept>
#include <sstream>

namespace shard::base
{
  std::string
  trim(const std::string &text)
  {
    const auto b = text.find_first_not_of(" \t\r\n");
    if (b == std::string::npos)
      return "";
    const auto e = text.find_last_not_of(" \t\r\n");
    return text.substr(b, e - b + 1);
  }

  std::vector<std::string>
  split(const std::string &text, const char separator)
  {
    std::vector<std::string> out;
    std::stringstream        in(text);
    std::string              item;
    while (std::getline(in, item, separator))
      if (const auto t = trim(item); !t.empty())
        out.push_back(t);
    return out;
  }

  std::vector<double>
  parse_numbers(const std::string &text)
  {
    std::istringstream  in(text);
    std::vector<double> values;
    std::string         word;
    while (in >> word)
      {
        std::size_t used = 0;
        double      value;
        try
          {
            value = std::stod(word, &used);
          }
        catch (const std::exception &)
          {
            used = 0;
          }
        if (used != word.size())
          throw std::invalid_argument("'" + word + "' is not a number");
        values.push_back(value);
      }
    return values;
  }

  std::string
  json_escape(const std::string &text)
  {
    std::string out;
    const auto  n = text.size();
    for (std::size_t i = 0; i < n; ++i)
      {
        const auto c = static_cast<unsigned char>(text[i]);
        if (c == '"' || c == '\\')
          {
            out += '\\';
            out += static_cast<char>(c);
          }
        else if (c == '\n')
          out += "\\n";
        else if (c == '\t')
          out += "\\t";
        else if (c < 0x20 || c == 0x7f)
          {
            char code[8];
            std::snprintf(code, sizeof(code), "\\u%04x", c);
            out += code;
          }
        else if (c < 0x80)
          out += static_cast<char>(c);
        else
          {
            // A UTF-8 sequence is copied whole; a byte that does not start a valid one becomes U+FFFD.
            const unsigned int length = (c >= 0xc2 && c <= 0xdf) ? 2 : (c >= 0xe0 && c <= 0xef) ? 3 :
                                        (c >= 0xf0 && c <= 0xf4) ? 4 : 0;
            bool valid = length > 0 && i + length <= n;
            for (unsigned int k = 1; valid && k < length; ++k)
              valid = (static_cast<unsigned char>(text[i + k]) & 0xc0) == 0x80;
            if (valid && length > 2)
              {
                // No overlong forms, surrogates or code points above U+10FFFF.
                const auto c1 = static_cast<unsigned char>(text[i + 1]);
                valid = !((c == 0xe0 && c1 < 0xa0) || (c == 0xed && c1 > 0x9f) || (c == 0xf0 && c1 < 0x90) ||
                          (c == 0xf4 && c1 > 0x8f));
              }
            if (valid)
              {
                out.append(text, i, length);
                i += length - 1;
              }
            else
              out += "\\ufffd";
          }
      }
    return out;
  }

  std::string
  printable(const std::string &text, const std::size_t max_length)
  {
    std::string out;
    for (const char ch : text)
      {
        if (out.size() >= max_length)
          {
            out += "...";
            break;
          }
        const auto c = static_cast<unsigned char>(ch);
        if (c >= 0x20 && c < 0x7f)
          out += ch;
        else
          {
            char code[8];
            std::snprintf(code, sizeof(code), "\\x%02x", c);
            out += code;
          }
      }
    return out;
  }

  std::string
  exception_reason(const std::exception &e)
  {
    std::string what = e.what();
    // deal.II's exceptions: the text after "Additional information:", without the stack trace.
    if (const auto at = what.find("Additional information:"); at != std::string::npos)
      what = what.substr(at + 23);
    if (const auto at = what.find("Stacktrace"); at != std::string::npos)
      what = what.substr(0, at);
    what = std::regex_replace(what, std::regex("-{8,}"), " ");
    what = std::regex_replace(what, std::regex("\\s+"), " ");
    what = trim(what);
    return printable(what.empty() ? std::string("unknown error") : what, 300);
  }

  std::vector<std::vector<double>>
  parse_table(const std::string &text, const unsigned int n_columns)
  {
    std::vector<std::vector<double>> rows;
    for (const auto &row_text : split(text, ';'))
      {
        std::vector<double> row = parse_numbers(row_text);
        if (row.size() != n_columns)
          throw std::invalid_argument("row '" + row_text + "' has " + std::to_string(row.size()) +
                                      " numbers, expected " + std::to_string(n_columns));
        rows.push_back(std::move(row));
      }
    return rows;
  }

  void
  check_names(const PrmSource &source, const std::string &path, const std::string &text,
              const std::vector<std::string> &names, const bool allow_empty)
  {
    if (names.empty() && !allow_empty)
      source.fail(path, text, "at least one name is required.");
    std::set<std::string> seen;
    for (const auto &name : names)
      {
        if (!std::regex_match(name, std::regex("[A-Za-z0-9_-]+")))
          source.fail(path, text, "'" + name + "' may use letters, digits, '_' and '-' only.");
        if (!seen.insert(name).second)
          source.fail(path, text, "'" + name + "' appears twice.");
      }
  }

  void
  write_file_atomically(const std::string &path, const std::string &content)
  {
    const std::string tmp = path + ".tmp";
    {
      std::ofstream out(tmp);
      out << content;
      if (!out)
        throw std::runtime_error("cannot write '" + tmp + "'");
    }
    std::filesystem::rename(tmp, path);
  }

  std::array<double, 3>
  parse_point(const std::string &text)
  {
    const auto items = split(text, ',');
    if (items.size() != 3)
      throw std::invalid_argument("expected three numbers 'x, y, z'");
    std::array<double, 3> p;
    for (unsigned int d = 0; d < 3; ++d)
      {
        std::size_t used = 0;
        try
          {
            p[d] = std::stod(items[d], &used);
          }
        catch (const std::exception &)
          {
            used = 0;
          }
        if (used != items[d].size())
          throw std::invalid_argument("'" + items[d] + "' is not a number");
        if (!std::isfinite(p[d]))
          throw std::invalid_argument("'" + items[d] + "' is not a finite number (every coordinate must be finite)");
      }
    return p;
  }

  namespace
  {
    std::string
    join_path(const std::vector<std::string> &sections, const std::string &key)
    {
      std::string path;
      for (const auto &s : sections)
        path += s + "/";
      return path + key;
    }

    /// Scans .prm text: "path/key" -> line (1-based), for every `set` line.
    std::map<std::string, unsigned int>
    scan_prm(const std::string &text)
    {
      std::map<std::string, unsigned int> lines;
      std::vector<std::string>            sections;
      std::istringstream                  in(text);
      std::string                         line;
      unsigned int                        number = 0;
      std::string                         pending;
      unsigned int                        pending_start = 0;
      while (std::getline(in, line))
        {
          ++number;
          // Continuation lines end in a backslash.
          if (!line.empty() && line.back() == '\\')
            {
              if (pending.empty())
                pending_start = number;
              pending += line.substr(0, line.size() - 1);
              continue;
            }
          unsigned int at = number;
          if (!pending.empty())
            {
              line          = pending + line;
              at            = pending_start;
              pending.clear();
            }
          if (const auto hash = line.find('#'); hash != std::string::npos)
            line.erase(hash);
          line = trim(line);
          if (line.rfind("subsection", 0) == 0)
            sections.push_back(trim(line.substr(10)));
          else if (line == "end")
            {
              if (!sections.empty())
                sections.pop_back();
            }
          else if (line.rfind("set ", 0) == 0)
            {
              const auto eq = line.find('=');
              if (eq != std::string::npos)
                lines[join_path(sections, trim(line.substr(4, eq - 4)))] = at;
            }
        }
      return lines;
    }

    /// Subsection path of the `set` line @p number in @p text (empty if none).
    std::vector<std::string>
    sections_at_line(const std::string &text, const unsigned int number)
    {
      std::vector<std::string> sections;
      std::istringstream       in(text);
      std::string              line;
      for (unsigned int n = 1; n < number && std::getline(in, line); ++n)
        {
          if (const auto hash = line.find('#'); hash != std::string::npos)
            line.erase(hash);
          line = trim(line);
          if (line.rfind("subsection", 0) == 0)
            sections.push_back(trim(line.substr(10)));
          else if (line == "end" && !sections.empty())
            sections.pop_back();
        }
      return sections;
    }

    unsigned int
    edit_distance(const std::string &a, const std::string &b)
    {
      std::vector<unsigned int> prev(b.size() + 1), cur(b.size() + 1);
      for (unsigned int j = 0; j <= b.size(); ++j)
        prev[j] = j;
      for (unsigned int i = 1; i <= a.size(); ++i)
        {
          cur[0] = i;
          for (unsigned int j = 1; j <= b.size(); ++j)
            cur[j] = std::min({prev[j] + 1, cur[j - 1] + 1,
                               prev[j - 1] + (a[i - 1] == b[j - 1] ? 0u : 1u)});
          std::swap(prev, cur);
        }
      return prev[b.size()];
    }

    /// A declared entry: its value and its documentation (from the PRM listing).
    struct Entry
    {
      std::string value, documentation;
    };

    /// Declared entries of @p prm by "path/key", read back from the PRM listing with documentation.
    std::map<std::string, Entry>
    declared_entries(const dealii::ParameterHandler &prm)
    {
      std::ostringstream out;
      prm.print_parameters(out, dealii::ParameterHandler::PRM);
      std::map<std::string, Entry> entries;
      std::vector<std::string>     sections;
      std::istringstream           in(out.str());
      std::string                  line, doc;
      while (std::getline(in, line))
        {
          line = trim(line);
          if (line.rfind("#", 0) == 0)
            {
              doc += (doc.empty() ? "" : " ") + trim(line.substr(1));
              continue;
            }
          if (line.rfind("subsection ", 0) == 0)
            sections.push_back(trim(line.substr(11)));
          else if (line == "end" && !sections.empty())
            sections.pop_back();
          else if (line.rfind("set ", 0) == 0)
            {
              const auto eq = line.find('=');
              if (eq != std::string::npos)
                {
                  std::string value = line.substr(eq + 1);
                  if (const auto hash = value.find('#'); hash != std::string::npos)
                    value.erase(hash);
                  entries[join_path(sections, trim(line.substr(4, eq - 4)))] = {trim(value), doc};
                }
            }
          doc.clear();
        }
      return entries;
    }

    /// Declared keys of @p prm, as "path/key".
    std::set<std::string>
    declared_keys(const dealii::ParameterHandler &prm)
    {
      std::set<std::string> keys;
      for (const auto &[path, entry] : declared_entries(prm))
        keys.insert(path);
      return keys;
    }

    /// "Did you mean ...?" for an unknown key @p key in the subsection @p sections.
    std::string
    suggestion(const dealii::ParameterHandler &prm, const std::vector<std::string> &sections, const std::string &key)
    {
      std::string prefix   = join_path(sections, "");
      std::string best;
      unsigned int best_distance = 4;
      std::vector<std::string> candidates;
      for (const auto &path : declared_keys(prm))
        if (path.rfind(prefix, 0) == 0 && path.find('/', prefix.size()) == std::string::npos)
          {
            const auto name = path.substr(prefix.size());
            candidates.push_back(name);
            if (const auto d = edit_distance(name, key); d < best_distance)
              best_distance = d, best = name;
          }
      std::string out;
      if (!best.empty())
        out += " Did you mean '" + best + "'?";
      if (!candidates.empty() && candidates.size() <= 20)
        {
          out += " Keys of subsection '" + (sections.empty() ? std::string("(top level)")
                                                              : prefix.substr(0, prefix.size() - 1)) +
                 "': ";
          for (unsigned int i = 0; i < candidates.size(); ++i)
            out += (i ? ", " : "") + candidates[i];
          out += ".";
        }
      return out;
    }

    /// Line @p number (1-based) of @p text, trimmed, without a comment.
    std::string
    line_of(const std::string &text, const unsigned int number)
    {
      std::istringstream in(text);
      std::string        line;
      for (unsigned int n = 1; n <= number && std::getline(in, line); ++n)
        if (n == number)
          {
            if (const auto hash = line.find('#'); hash != std::string::npos)
              line.erase(hash);
            return trim(line);
          }
      return "";
    }

    /// The subsection @p name is not declared below @p sections: the declared ones, and the
    /// list key that names them (a named subsection exists once its name is in that list).
    std::string
    unknown_subsection(const dealii::ParameterHandler &prm, const std::vector<std::string> &sections,
                       const std::string &name)
    {
      const std::string prefix  = join_path(sections, "");
      const auto        entries = declared_entries(prm);
      std::set<std::string> children;
      for (const auto &[path, entry] : entries)
        if (path.rfind(prefix, 0) == 0)
          if (const auto slash = path.find('/', prefix.size()); slash != std::string::npos)
            children.insert(path.substr(prefix.size(), slash - prefix.size()));
      std::string out = "unknown subsection '" + name + "'" +
                        (sections.empty() ? std::string() : " in '" + prefix.substr(0, prefix.size() - 1) + "'") + ".";
      std::string declared;
      for (const auto &c : children)
        declared += (declared.empty() ? "" : ", ") + c;
      // The list key of this section whose value names subsections of it.
      for (const auto &[path, entry] : entries)
        if (path.rfind(prefix, 0) == 0 && path.find('/', prefix.size()) == std::string::npos)
          {
            const auto items = split(entry.value, ',');
            if (std::any_of(items.begin(), items.end(), [&](const std::string &i) { return children.count(i) > 0; }))
              return out + " A named subsection exists only when its name is listed in '" + path +
                     "' (declared now: " + declared + "): add '" + name +
                     "' to that list (in the file or with --set), or correct the name.";
          }
      if (!children.empty())
        {
          out += " Subsections here: ";
          bool first = true;
          for (const auto &c : children)
            out += (first ? "" : ", ") + c, first = false;
          out += ".";
        }
      return out;
    }

    /// What a value of @p pattern (deal.II's description) must be, in words.
    std::string
    pattern_in_words(const std::string &pattern)
    {
      std::smatch m;
      const auto  bound = [](std::string x) { return x == "MAX_DOUBLE" ? std::string() : x == "-MAX_DOUBLE" ? std::string() : x; };
      if (std::regex_search(pattern, m, std::regex("Double (\\S+)\\.\\.\\.(\\S+)")))
        {
          const auto lo = bound(m[1]), hi = bound(m[2]);
          return lo.empty() && hi.empty() ? "a finite number" :
                 hi.empty()               ? "a number >= " + lo :
                 lo.empty()               ? "a number <= " + hi :
                                            "a number from " + lo + " to " + hi;
        }
      if (std::regex_search(pattern, m, std::regex("Integer range (\\S+)\\.\\.\\.(\\S+)")))
        {
          const std::string lo = m[1], hi = m[2];
          return hi == "MAX_INT" || hi == "2147483647" ? "a whole number >= " + lo : "a whole number from " + lo + " to " + hi;
        }
      if (std::regex_search(pattern, m, std::regex("Selection (.*?) *\\]")))
        return "one of: " + std::regex_replace(std::string(m[1]), std::regex("\\|"), ", ");
      if (pattern.find("Bool") != std::string::npos)
        return "true or false";
      return "a value of the form " + pattern;
    }

    /// The "Range: ... ." and "Unit: ... ." sentences of a key's documentation.
    std::string
    documented_range(const std::string &doc, const std::string &what)
    {
      const auto sentence = [&](const std::string &label) {
        const auto at = doc.find(label);
        if (at == std::string::npos)
          return std::string();
        std::smatch m;
        const std::string rest = doc.substr(at + label.size());
        if (std::regex_search(rest, m, std::regex("^\\s*(.*?)\\.(\\s+[A-Z(]|\\s*$)")))
          return trim(m[1]);
        return trim(rest);
      };
      const auto range = sentence("Range:"), unit = sentence("Unit:");
      std::string out  = "must be " + what + (range.empty() ? std::string() : " (documented range: " + range + ")") + ".";
      if (!unit.empty())
        out += " Unit: " + unit + ".";
      return out;
    }

    /// Turns deal.II's parse errors into one located line. @p overrides is the --set text.
    [[noreturn]] void
    rethrow_parse_error(const dealii::ExceptionBase &e, const dealii::ParameterHandler &prm,
                        const PrmSource &source, const std::string &overrides)
    {
      std::ostringstream info;
      e.print_info(info);
      std::string msg = info.str();
      // Collapse deal.II's multi-line layout to one line.
      msg = std::regex_replace(msg, std::regex("\\s*\\n\\s*"), " ");
      msg = trim(msg);
      std::smatch m;
      if (std::regex_search(msg, m, std::regex("Line <(\\d+)> of file <(.*)$")))
        {
          const unsigned int line = std::stoul(m[1]);
          std::string        rest = m[2];
          // deal.II 9.4 writes "<file>: reason" or "<file: reason": the file is known.
          const bool         from_set = rest.rfind("--set", 0) == 0;
          const std::string &file     = from_set ? std::string("--set") : source.filename();
          if (rest.rfind(file, 0) == 0)
            rest = rest.substr(file.size());
          else if (const auto gt = rest.find('>'); gt != std::string::npos)
            rest = rest.substr(gt);
          const auto start = rest.find_first_not_of(">: ");
          std::string reason = start == std::string::npos ? std::string() : rest.substr(start);
          const std::string &text     = from_set ? overrides : source.text();
          const auto         sections = sections_at_line(text, line);
          const auto         where    = [&](const std::string &key) {
            return from_set ? "--set " + join_path(sections, key) : file + ":" + std::to_string(line);
          };
          std::smatch k;
          if (std::regex_search(reason, k, std::regex("No entry with name <([^>]*)> was declared")))
            throw InputError(where(k[1]) + ": unknown key '" + std::string(k[1]) + "'." +
                             suggestion(prm, sections, k[1]));
          if (std::regex_search(reason, k, std::regex("[Nn]o such subsection to be entered")))
            {
              const auto  statement = line_of(text, line);
              std::string name = statement.rfind("subsection", 0) == 0 ? trim(statement.substr(10)) : std::string();
              throw InputError((from_set ? "--set " + join_path(sections, name) : where("")) + ": " +
                               unknown_subsection(prm, sections, name));
            }
          if (std::regex_search(reason, k,
                                std::regex("The entry value <?(.*?)>? for the entry named <?(.*?)>? does not match "
                                           "the given pattern:? <?(.*?)>?\\.?$")))
            {
              const std::string value = k[1], key = k[2], pattern = k[3];
              const auto        path    = join_path(sections, key);
              const auto        entries = declared_entries(prm);
              const auto        it      = entries.find(path);
              throw InputError(where(key) + ": " + path + " = " + printable(value, 80) + ": " +
                               documented_range(it == entries.end() ? std::string() : it->second.documentation,
                                                pattern_in_words(pattern)));
            }
          throw InputError(where("") + ": " + printable(reason, 300));
        }
      throw InputError(printable(msg, 300));
    }
  } // namespace

  PrmSource::PrmSource(const std::string &filename)
    : filename_(filename)
  {
    std::error_code error;
    if (std::filesystem::is_directory(filename, error))
      throw InputError(filename + ": is a directory, not a parameter file: give the path of a .prm file.");
    std::ifstream in(filename);
    if (!in)
      throw InputError(filename + ": cannot open the parameter file for reading.");
    std::ostringstream buffer;
    buffer << in.rdbuf();
    text_  = buffer.str();
    lines_ = scan_prm(text_);
  }

  void
  PrmSource::add_override(const std::string &assignment)
  {
    const auto refuse = [&](const std::string &why) {
      throw CommandLineError("malformed --set '" + printable(assignment, 120) + "': " + why +
                             " Expected the form \"Section/Subsection/key=value\".");
    };
    const auto eq = assignment.find('=');
    if (eq == std::string::npos)
      refuse("no '='.");
    const std::string path = trim(assignment.substr(0, eq)), value = trim(assignment.substr(eq + 1));
    for (const char c : assignment)
      if (c == '\n' || c == '\r')
        refuse("a line break in the key or value (it would add statements to the scene).");
    if (!value.empty() && value.back() == '\\')
      refuse("the value ends in '\\', which would continue the line.");
    if (path.find('#') != std::string::npos)
      refuse("'#' in the key.");
    if (path.find('/') == std::string::npos)
      refuse("the key has no section ('Section/key').");
    // Every part of the path is a non-empty name: "/=1", "A//b=1" and "A/=1" are refused.
    std::vector<std::string> parts;
    std::size_t              begin = 0;
    while (true)
      {
        const auto slash = path.find('/', begin);
        parts.push_back(trim(path.substr(begin, slash == std::string::npos ? std::string::npos : slash - begin)));
        if (slash == std::string::npos)
          break;
        begin = slash + 1;
      }
    for (const auto &part : parts)
      if (part.empty())
        refuse("an empty section or key name in '" + printable(path, 120) + "'.");
    overrides_.emplace_back(path, value);
  }

  std::string
  PrmSource::directory() const
  {
    const auto slash = filename_.rfind('/');
    return slash == std::string::npos ? std::string() : filename_.substr(0, slash + 1);
  }

  std::string
  PrmSource::overrides_as_prm() const
  {
    std::string out;
    for (const auto &[path, value] : overrides_)
      {
        const auto parts = split(path, '/');
        for (unsigned int i = 0; i + 1 < parts.size(); ++i)
          out += "subsection " + parts[i] + "\n";
        out += "set " + parts.back() + " = " + value + "\n";
        for (unsigned int i = 0; i + 1 < parts.size(); ++i)
          out += "end\n";
      }
    return out;
  }

  std::string
  PrmSource::locate(const std::string &path) const
  {
    for (const auto &o : overrides_)
      if (o.first == path)
        return "--set " + path;
    if (const auto it = lines_.find(path); it != lines_.end())
      return filename_ + ":" + std::to_string(it->second);
    return (filename_.empty() ? std::string("default") : filename_ + ": default");
  }

  void
  PrmSource::fail(const std::string &path, const std::string &value,
                  const std::string &requirement) const
  {
    throw InputError(locate(path) + ": " + path + " = " + value + ": " + requirement);
  }

  void
  read_parameters(dealii::ParameterHandler &prm, const std::vector<ParameterOwner *> &owners,
                  const PrmSource &source)
  {
    const std::string overrides = source.overrides_as_prm();
    const auto        parse     = [&](const bool skip_undefined) {
      try
        {
          if (!source.text().empty())
            {
              std::istringstream in(source.text());
              prm.parse_input(in, source.filename(), "", skip_undefined);
            }
          if (!overrides.empty())
            {
              std::istringstream in(overrides);
              prm.parse_input(in, "--set", "", skip_undefined);
            }
        }
      catch (const dealii::ExceptionBase &e)
        {
          rethrow_parse_error(e, prm, source, overrides);
        }
    };
    for (unsigned int round = 0; round < 16; ++round)
      {
        bool new_entries = false;
        for (auto *owner : owners)
          new_entries = owner->declare_parameters(prm) || new_entries;
        if (!new_entries && round > 0)
          break;
        parse(true);
      }
    parse(false);
    for (auto *owner : owners)
      owner->check_parameters(source);
  }
} // namespace shard::base
