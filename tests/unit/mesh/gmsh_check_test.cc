// SPDX-License-Identifier: LGPL-2.1-or-later
// Structural check of Gmsh ASCII files (mesh::check_gmsh): one test per rule on small in-memory
// files of one hexahedron (version 2.2 and 4.1), each checking the line and a key phrase of the
// one-line message; the real meshes of prm/ are read from disk and must pass with the right counts.
#include <shard/mesh/gmsh_check.h>

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace
{
  using shard::mesh::check_gmsh;
  using shard::mesh::GmshError;
  using Lines = std::vector<std::string>;

  std::string
  join(const Lines &lines, const std::string &end = "\n")
  {
    std::string text;
    for (const auto &l : lines)
      text += l + end;
    return text;
  }

  /// One hexahedron and one boundary quadrilateral, version 2.2 (line numbers in comments).
  Lines
  v22()
  {
    return {"$MeshFormat",          // 1
            "2.2 0 8",              // 2
            "$EndMeshFormat",       // 3
            "$Nodes",               // 4
            "8",                    // 5
            "1 0 0 0",              // 6
            "2 1 0 0",              // 7
            "3 1 1 0",              // 8
            "4 0 1 0",              // 9
            "5 0 0 1",              // 10
            "6 1 0 1",              // 11
            "7 1 1 1",              // 12
            "8 0 1 1",              // 13
            "$EndNodes",            // 14
            "$Elements",            // 15
            "2",                    // 16
            "1 3 2 1 1 1 2 3 4",    // 17
            "2 5 2 1 1 1 2 3 4 5 6 7 8", // 18
            "$EndElements"};        // 19
  }

  /// The same mesh in version 4.1 with $Entities (line numbers in comments).
  Lines
  v41()
  {
    Lines l = {"$MeshFormat",                  // 1
               "4.1 0 8",                      // 2
               "$EndMeshFormat",               // 3
               "$Entities",                    // 4
               "0 0 1 1",                      // 5
               "1 0 0 0 1 1 0 1 3 4 1 2 3 4",  // 6: surface 1, physical 3, 4 bounding curves
               "1 0 0 0 1 1 1 1 1 1 1",        // 7: volume 1, physical 1, 1 bounding surface
               "$EndEntities",                 // 8
               "$Nodes",                       // 9
               "1 8 1 8",                      // 10
               "3 1 0 8"};                     // 11
    for (int i = 1; i <= 8; ++i) // 12-19
      l.push_back(std::to_string(i));
    for (const char *x : {"0 0 0", "1 0 0", "1 1 0", "0 1 0", "0 0 1", "1 0 1", "1 1 1", "0 1 1"}) // 20-27
      l.push_back(x);
    for (const char *x : {"$EndNodes",                  // 28
                          "$Elements",                  // 29
                          "2 2 1 2",                    // 30
                          "2 1 3 1",                    // 31
                          "1 1 2 3 4",                  // 32
                          "3 1 5 1",                    // 33
                          "2 1 2 3 4 5 6 7 8",          // 34
                          "$EndElements"})              // 35
      l.push_back(x);
    return l;
  }

  /// Lines @p l with line @p n (1-based) replaced by @p text.
  Lines
  with(Lines l, const std::size_t n, const std::string &text)
  {
    l.at(n - 1) = text;
    return l;
  }

  /// Lines @p l with @p text inserted before line @p n (1-based; size() + 1 appends).
  Lines
  inserting(Lines l, const std::size_t n, const std::string &text)
  {
    l.insert(l.begin() + static_cast<long>(n - 1), text);
    return l;
  }

  /// Lines @p l without lines @p first..@p last (1-based, inclusive).
  Lines
  without(Lines l, const std::size_t first, const std::size_t last)
  {
    l.erase(l.begin() + static_cast<long>(first - 1), l.begin() + static_cast<long>(last));
    return l;
  }

  /// The message check_gmsh() throws for @p in ("accepted" if none); checks that it is one printable line.
  std::string
  message(std::istream &in)
  {
    try
      {
        check_gmsh(in);
      }
    catch (const GmshError &e)
      {
        const std::string what = e.what();
        for (const char c : what)
          EXPECT_TRUE(c >= 0x20 && c <= 0x7e) << "byte " << int(static_cast<unsigned char>(c)) << " in " << what;
        EXPECT_EQ(what, "line " + std::to_string(e.line()) + ": " + e.problem());
        return what;
      }
    return "accepted";
  }

  std::string
  message(const std::string &text)
  {
    std::istringstream in(text);
    return message(in);
  }

  std::string
  message(const Lines &lines)
  {
    return message(join(lines));
  }

  /// Expects @p text refused at line @p line with a message containing @p phrase.
  void
  expect_refused(const std::string &text, const unsigned long long line, const std::string &phrase)
  {
    const std::string m = message(text);
    EXPECT_EQ(m.rfind("line " + std::to_string(line) + ": ", 0), 0u) << m;
    EXPECT_NE(m.find(phrase), std::string::npos) << m;
  }

  void
  expect_refused(const Lines &lines, const unsigned long long line, const std::string &phrase)
  {
    expect_refused(join(lines), line, phrase);
  }

  shard::mesh::GmshSummary
  summary(const std::string &text)
  {
    std::istringstream in(text);
    return check_gmsh(in);
  }

  /// The prm/ folder of the source tree (the tests run in tests/ or at the top).
  std::filesystem::path
  prm_folder()
  {
    for (const char *p : {"../prm", "prm"})
      if (std::filesystem::is_directory(p))
        return p;
    return {};
  }
} // namespace

// --- valid files ---

TEST(GmshCheck, Valid22OneHexahedron)
{
  const auto s = summary(join(v22()));
  EXPECT_EQ(s.n_nodes, 8u);
  EXPECT_EQ(s.n_hexahedra, 1u);
  EXPECT_EQ(s.n_elements, 2u);
  EXPECT_DOUBLE_EQ(s.version, 2.2);
}

TEST(GmshCheck, Valid41OneHexahedron)
{
  const auto s = summary(join(v41()));
  EXPECT_EQ(s.n_nodes, 8u);
  EXPECT_EQ(s.n_hexahedra, 1u);
  EXPECT_EQ(s.n_elements, 2u);
  EXPECT_DOUBLE_EQ(s.version, 4.1);
}

TEST(GmshCheck, ValidVariants)
{
  // CRLF line ends, blank lines, no final line end.
  EXPECT_EQ(message(join(v22(), "\r\n")), "accepted");
  EXPECT_EQ(message(join(inserting(v22(), 4, ""))), "accepted");
  auto text = join(v41());
  text.pop_back();
  EXPECT_EQ(message(text), "accepted");
  // $PhysicalNames before $Nodes (UTF-8 in a name is text) and any section after $Elements.
  EXPECT_EQ(message(inserting(inserting(inserting(v22(), 4, "$PhysicalNames"), 5, "1\n2 1 \"b\xc3\xa9ton\""), 6,
                              "$EndPhysicalNames")),
            "accepted");
  auto l = v41();
  l.insert(l.end(), {"$Periodic", "0", "$EndPeriodic", "$Comments", "anything $Nodes", "$EndComments"});
  EXPECT_EQ(message(l), "accepted");
  // Versions 2.0 and 2.1 share the 2.2 layout; unsorted node tags; sparse node tags.
  EXPECT_EQ(message(with(v22(), 2, "2.1 0 8")), "accepted");
  EXPECT_EQ(message(with(with(v22(), 6, "8 0 0 0"), 13, "1 0 1 1")), "accepted");
  EXPECT_EQ(message(with(with(with(v22(), 6, "1000 0 0 0"), 17, "1 3 2 1 1 1000 2 3 4"), 18,
                         "2 5 2 1 1 1000 2 3 4 5 6 7 8")),
            "accepted");
  // A coordinate that underflows reads as 0, as operator>> reads it; '+' signs and exponents.
  EXPECT_EQ(message(with(v22(), 7, "2 1e-400 +0.0 -0E+00")), "accepted");
  // A parametric node block on a surface: x y z u v.
  auto p = with(v41(), 11, "2 1 1 8");
  for (std::size_t i = 20; i <= 27; ++i)
    p[i - 1] += " 0.5 0.5";
  EXPECT_EQ(message(with(p, 31, "2 1 3 1")), "accepted");
}

// --- the stream and the bytes ---

TEST(GmshCheck, EmptyFile)
{
  expect_refused("", 1, "the file is empty");
  expect_refused("\n  \n\t\n", 1, "the file is empty");
  std::ifstream in("/dev/null");
  EXPECT_NE(message(in).find("line 1: the file is empty"), std::string::npos);
}

TEST(GmshCheck, UnreadableStream)
{
  std::ifstream missing("no/such/file.msh");
  EXPECT_NE(message(missing).find("line 1: the file cannot be read"), std::string::npos);
  std::ifstream directory(".");
  EXPECT_NE(message(directory).find("line 1: the file cannot be read (is it a directory?)"), std::string::npos);
  std::istringstream failed(join(v22()));
  failed.setstate(std::ios_base::failbit);
  EXPECT_NE(message(failed).find("line 1: the file cannot be read"), std::string::npos);
  // A stream that throws on failure reads the same.
  std::istringstream throwing(join(v22()));
  throwing.exceptions(std::ios_base::failbit | std::ios_base::badbit);
  EXPECT_EQ(message(throwing), "accepted");
  std::ifstream throwing_directory(".");
  throwing_directory.exceptions(std::ios_base::failbit | std::ios_base::badbit);
  EXPECT_NE(message(throwing_directory).find("line 1: the file cannot be read (is it a directory?)"), std::string::npos);
}

TEST(GmshCheck, ByteThatIsNotText)
{
  expect_refused(join(with(v22(), 7, std::string("2 1 0\0 0", 8))), 7, "a byte that is not text (\\x00) at column 6");
  auto l = v22();
  l.insert(l.end(), {"$Comments", "\x1b[31m", "$EndComments"});
  expect_refused(l, 21, "a byte that is not text (\\x1b)");
  expect_refused(join(with(v22(), 9, "4 0 1 0\x7f")), 9, "(\\x7f)");
  expect_refused(std::string(100, '\0'), 1, "(\\x00)");
}

TEST(GmshCheck, LineTooLong)
{
  expect_refused("$MeshFormat\n" + std::string(9 << 20, 'x') + "\n", 2, "a line longer than");
}

TEST(GmshCheck, ExcerptIsShortAndPrintable)
{
  const std::string m = message(std::string(60, 'a') + "\xff\xfe\n");
  EXPECT_EQ(m, "line 1: a Gmsh file starts with $MeshFormat; found '" + std::string(40, 'a') + "...'");
  expect_refused("\xc3\xa9t\xc3\xa9\n", 1, "found '\\xc3\\xa9t\\xc3\\xa9'");
}

// --- $MeshFormat ---

TEST(GmshCheck, StartsWithMeshFormat)
{
  expect_refused("1h(@/_Y\\sP:,^#QWm yYB|=k-H#\"#se!Pw;V|#c<X_f=L=v<ZE\"Ugr,7p\n", 1,
                 "a Gmsh file starts with $MeshFormat; found '1h(@/_Y\\sP:,^#QWm yYB|=k-H#\"#se!Pw;V|#c<...'");
  expect_refused("$NOD\n8\n", 1, "Gmsh format 1");
  expect_refused(join(without(v22(), 1, 1)), 1, "found '2.2 0 8'");
}

TEST(GmshCheck, VersionLine)
{
  expect_refused(join(with(v22(), 2, "4.1 0")), 2, "3 numbers (version file-type data-size");
  expect_refused(join(with(v22(), 2, "3.0 0 8")), 2,
                 "version '3.0' is not supported: shard reads ASCII versions 2.2 and 4.1");
  expect_refused(join(with(v22(), 2, "4 0 8")), 2, "is not supported");
  expect_refused(join(with(v22(), 2, "x 0 8")), 2, "the version 'x' is not a number");
  expect_refused(join(with(v22(), 2, "2.2 0 4")), 2, "data-size '4' is not 8");
  expect_refused(join(with(v22(), 2, "2.2 2 8")), 2, "file-type '2' is not 0 (ASCII) or 1 (binary)");
  expect_refused(join(without(v22(), 2, 19)), 1, "$MeshFormat is not ended by $EndMeshFormat");
  expect_refused(join(without(v22(), 3, 3)), 3, "expected $EndMeshFormat after the version line; found '$Nodes'");
}

TEST(GmshCheck, BinaryFile)
{
  // A binary file: the version line is text, then a binary int 1 before $EndMeshFormat.
  const std::string binary = std::string("$MeshFormat\n4.1 1 8\n\x01\0\0\0\n$EndMeshFormat\n", 37);
  expect_refused(binary, 2, "binary Gmsh files are not supported (file-type 1): save as ASCII");
}

// --- sections ---

TEST(GmshCheck, UnterminatedSection)
{
  auto l = v22();
  l.insert(l.end(), {"$Comments", "text"});
  expect_refused(l, 20, "$Comments is not ended by $EndComments (the file ends at line 21)");
  // deal.II skips $PhysicalNames token by token until its end: unterminated, it never stops.
  expect_refused(inserting(inserting(v22(), 4, "$PhysicalNames"), 5, "1\n3 1 \"a\""), 4,
                 "$PhysicalNames is not ended by $EndPhysicalNames");
  expect_refused(without(v22(), 19, 19), 15, "$Elements is not ended by $EndElements: the file ends at line 18");
  expect_refused(without(v41(), 8, 8), 8, "expected $EndEntities after 2 entities (the header is at line 5); found "
                                          "'$Nodes'");
}

TEST(GmshCheck, StrayLines)
{
  expect_refused(inserting(v22(), 4, "hello"), 4, "expected a section such as $Nodes or $Elements; found 'hello'");
  expect_refused(inserting(v22(), 20, "$EndNodes"), 20, "'$EndNodes' ends no open section");
  expect_refused(inserting(v22(), 4, "$Nodes 8"), 4, "expected a section");
}

TEST(GmshCheck, SectionOrder)
{
  expect_refused(inserting(inserting(v22(), 4, "$Comments"), 5, "$EndComments"), 4,
                 "'$Comments' before $Nodes: deal.II 9.4 reads only $PhysicalNames between $EndMeshFormat and $Nodes");
  expect_refused(inserting(inserting(v22(), 4, "$Entities"), 5, "$EndEntities"), 4, "'$Entities' before $Nodes");
  // Version 4.1: $PhysicalNames must come before $Entities.
  expect_refused(inserting(inserting(v41(), 9, "$PhysicalNames"), 10, "$EndPhysicalNames"), 9,
                 "only $PhysicalNames, $Entities and $PartitionedEntities, in this order");
  expect_refused(inserting(inserting(v22(), 15, "$Periodic"), 16, "$EndPeriodic"), 15,
                 "$Elements must follow $EndNodes");
  expect_refused(without(v22(), 4, 14), 4, "$Elements before $Nodes");
}

TEST(GmshCheck, RequiredSections)
{
  expect_refused(without(v22(), 4, 19), 3, "no $Nodes section");
  expect_refused(without(v22(), 15, 19), 14, "no $Elements section: the file ends after $EndNodes");
  auto l = v22();
  l.insert(l.end(), {"$Nodes", "0", "$EndNodes"});
  expect_refused(l, 20, "a second $Nodes section (the first is at line 4)");
  expect_refused(inserting(inserting(v22(), 20, "$Elements"), 21, "$EndElements"), 20,
                 "a second $Elements section (the first is at line 15)");
  expect_refused(inserting(inserting(v22(), 4, "$MeshFormat"), 5, "$EndMeshFormat"), 4, "a second $MeshFormat");
}

// --- version 2.2 nodes ---

TEST(GmshCheck, Nodes22Header)
{
  expect_refused(with(v22(), 5, "1 8 1 8"), 5,
                 "the $Nodes header of a version 2.2 file has 1 number (the node count); found 4: is this a version "
                 "4.1 file with a 2.2 header?");
  expect_refused(with(v22(), 5, "-1"), 5, "the node count '-1' is not an integer in 0..2147483647");
  expect_refused(with(v22(), 5, "4294967304"), 5, "not an integer in 0..2147483647");
  expect_refused(with(v22(), 5, "8.0"), 5, "the node count '8.0' is not an integer");
  expect_refused(without(v22(), 5, 19), 4, "$Nodes has no count line");
}

TEST(GmshCheck, TruncatedNodes)
{
  // The file ends inside $Nodes; a count far beyond the lines present reads only those lines.
  expect_refused(without(v22(), 11, 19), 4,
                 "$Nodes is not ended by $EndNodes: the file ends at line 10, at node line 6 of 8");
  expect_refused(without(with(v22(), 5, "2000000000"), 14, 19), 4, "at node line 9 of 2000000000");
  // Fewer node lines than the count, then $EndNodes.
  expect_refused(with(v22(), 5, "9"), 14, "'$EndNodes' where node line 9 of 9 was expected (the count is at line 5)");
  // More node lines than the count.
  expect_refused(with(v22(), 5, "7"), 13,
                 "expected $EndNodes after 7 node lines (the count is at line 5); found '8 0 1 1'");
}

TEST(GmshCheck, NodeLine22)
{
  expect_refused(with(v22(), 8, "3 1 1"), 8, "a node line of a version 2.2 file has 4 numbers (tag x y z); found 3");
  expect_refused(with(v22(), 8, "0 1 1 0"), 8, "the node tag '0' is not an integer in 1..2147483647");
  expect_refused(with(v22(), 8, "2147483648 1 1 0"), 8, "the node tag '2147483648'");
  expect_refused(with(v22(), 8, "3.5 1 1 0"), 8, "the node tag '3.5'");
  expect_refused(with(v22(), 8, "3 1 1 x"), 8, "the coordinate 'x' is not a number");
  expect_refused(with(v22(), 8, "3 1 1,0 0"), 8, "the coordinate '1,0' is not a number");
  expect_refused(with(v22(), 8, "3 0x10 1 0"), 8, "the coordinate '0x10' is not a number");
}

TEST(GmshCheck, CoordinateNotFinite)
{
  expect_refused(with(v22(), 8, "3 1e400 1 0"), 8, "the coordinate '1e400' is not a finite number");
  expect_refused(with(v22(), 8, "3 1 -1e400 0"), 8, "'-1e400' is not a finite number");
  expect_refused(with(v22(), 8, "3 1 1 nan"), 8, "'nan' is not a finite number");
  expect_refused(with(v22(), 8, "3 inf 1 0"), 8, "'inf' is not a finite number");
  expect_refused(with(v41(), 22, "1 1e400 0"), 22, "'1e400' is not a finite number");
}

TEST(GmshCheck, DuplicateNodeTag)
{
  expect_refused(with(v22(), 10, "2 0 0 1"), 10, "node tag 2 appears twice (also at line 7)");
  expect_refused(with(v41(), 15, "1"), 15, "node tag 1 appears twice (also at line 12)");
}

// --- version 2.2 elements ---

TEST(GmshCheck, Elements22Header)
{
  expect_refused(with(v22(), 16, "2 2 1 2"), 16, "the $Elements header of a version 2.2 file has 1 number (the element "
                                                 "count); found 4: is this a version 4.1 file with a 2.2 header?");
  expect_refused(with(v22(), 16, "3"), 19, "'$EndElements' where element line 3 of 3 was expected");
  expect_refused(with(v22(), 16, "1"), 18, "expected $EndElements after 1 element lines");
  expect_refused(without(v22(), 18, 19), 15, "$Elements is not ended by $EndElements: the file ends at line 17, at "
                                             "element line 2 of 2");
}

TEST(GmshCheck, ElementNodeCount)
{
  expect_refused(with(v22(), 18, "2 5 2 1 1 1 2 3 4 5 6 7"), 18,
                 "an element of type 5 (hexahedron) with 2 tags has 13 numbers (tag type n-tags, 2 tags, 8 nodes); "
                 "found 12");
  expect_refused(with(v22(), 17, "1 3 0 1 2 3 4 5"), 17, "type 3 (quadrilateral) with 0 tags has 7 numbers");
  expect_refused(with(v22(), 17, "1 3"), 17, "an element line of a version 2.2 file is 'tag type n-tags tag... "
                                             "node...'; found 2 numbers");
  // Lines (2 nodes) and points (1 node) on the boundary are read.
  const auto s = summary(join(inserting(inserting(with(v22(), 16, "4"), 17, "3 1 0 1 2"), 17, "4 15 1 7 8")));
  EXPECT_EQ(s.n_elements, 4u);
  EXPECT_EQ(s.n_hexahedra, 1u);
}

TEST(GmshCheck, ElementType)
{
  expect_refused(with(v22(), 17, "1 99 0 1 2 3 4"), 17, "element type 99 is not supported");
  expect_refused(with(v22(), 17, "1 12 0 1 2 3 4"), 17,
                 "element type 12 (27-node second-order hexahedron) is not supported: shard reads first-order "
                 "hexahedra; save with Mesh.ElementOrder = 1");
  expect_refused(with(v22(), 17, "1 4 0 1 2 3 4"), 17, "element type 4 (tetrahedron): shard meshes bodies with "
                                                       "hexahedra only");
  expect_refused(with(v22(), 17, "1 6 0 1 2 3 4 5 6"), 17, "element type 6 (prism)");
  expect_refused(with(v22(), 17, "1 7 0 1 2 3 4 5"), 17, "element type 7 (pyramid)");
  expect_refused(with(v22(), 17, "1 2 0 1 2 3"), 17, "element type 2 (triangle)");
  expect_refused(with(v41(), 33, "3 1 6 1"), 33, "element type 6 (prism)");
}

TEST(GmshCheck, MissingNode)
{
  expect_refused(with(v22(), 18, "2 5 2 1 1 1 2 3 4 5 6 7 9"), 18,
                 "element 2 refers to node '9', which is not in $Nodes");
  expect_refused(with(v22(), 17, "1 3 2 1 1 1 2 3 0"), 17, "element 1 refers to node '0'");
  expect_refused(with(v41(), 34, "2 1 2 3 4 5 6 7 -8"), 34, "element 2 refers to node '-8'");
  // Sparse tags: a tag between two present tags is missing too.
  expect_refused(with(with(with(v22(), 6, "1000 0 0 0"), 17, "1 3 2 1 1 1000 2 3 4"), 18,
                      "2 5 2 1 1 500 2 3 4 5 6 7 8"),
                 18, "refers to node '500'");
}

TEST(GmshCheck, BoundaryIdRange)
{
  // The physical tag of a boundary element becomes a boundary id (0..254); a volume's is free.
  expect_refused(with(v22(), 17, "1 3 2 300 1 1 2 3 4"), 17,
                 "the physical tag 300 of element 1 (a quadrilateral) becomes a boundary id, which must be 0..254");
  expect_refused(with(v22(), 17, "1 3 2 -1 1 1 2 3 4"), 17, "physical tag -1");
  EXPECT_EQ(message(with(v22(), 18, "2 5 2 300 1 1 2 3 4 5 6 7 8")), "accepted");
  expect_refused(with(v41(), 6, "1 0 0 0 1 1 0 1 255 4 1 2 3 4"), 6,
                 "the physical tag 255 of surface 1 becomes a boundary id, which must be 0..254");
}

TEST(GmshCheck, NoHexahedra)
{
  expect_refused(without(with(v22(), 16, "1"), 18, 18), 15,
                 "no hexahedra (gmsh type 5): shard meshes bodies with hexahedra only");
  expect_refused(with(without(v41(), 31, 34), 30, "0 0 0 0"), 29, "no hexahedra (gmsh type 5)");
}

// --- version 4.1 ---

TEST(GmshCheck, Nodes41Header)
{
  // A version 2.2 body under a 4.1 header (deal.II 9.4 allocates until the machine kills it).
  auto l = v22();
  l[1]   = "4.1 0 8";
  expect_refused(l, 5,
                 "the $Nodes header of a version 4.1 file has 4 numbers (blocks, nodes, smallest tag, largest tag); "
                 "found 1: is this a version 2.2 file with a 4.1 header?");
  expect_refused(with(v41(), 10, "1 8 1"), 10, "found 3");
  expect_refused(with(v41(), 10, "1 8 1 5"), 10, "declares 8 nodes with tags 1..5: too few tags for distinct nodes");
  expect_refused(with(v41(), 10, "1 8 0 8"), 10, "the smallest node tag '0' is not an integer in 1..2147483647");
  expect_refused(with(v41(), 10, "1 8 1 4294967296"), 10, "the largest node tag '4294967296'");
}

TEST(GmshCheck, Nodes41Blocks)
{
  expect_refused(with(v41(), 11, "3 1 0"), 11, "a node block header of a version 4.1 file has 4 numbers (entity "
                                               "dimension, entity tag, parametric, nodes in block); found 3");
  expect_refused(with(v41(), 11, "3 1 0 9"), 11, "the node blocks hold more than the 8 nodes of the $Nodes header "
                                                 "(line 10)");
  expect_refused(with(v41(), 11, "3 1 0 -2"), 11, "the number of nodes in the block '-2' is not an integer");
  expect_refused(with(v41(), 11, "4 1 0 8"), 11, "the entity dimension '4' is not an integer in 0..3");
  expect_refused(with(v41(), 11, "3 1 2 8"), 11, "the parametric flag '2' is not an integer in 0..1");
  expect_refused(with(v41(), 11, "3 1 1 8"), 11, "parametric node coordinates on an entity of dimension 3: deal.II 9.4 "
                                                 "reads them only on surfaces");
  // The blocks hold fewer nodes than the header.
  expect_refused(without(without(with(v41(), 11, "3 1 0 7"), 27, 27), 19, 19), 26,
                 "the 1 node blocks hold 7 nodes; the $Nodes header (line 10) declares 8");
  // More blocks than the header: the next line must end $Nodes.
  expect_refused(inserting(v41(), 28, "3 1 0 0"), 28, "expected $EndNodes after 1 node blocks");
  expect_refused(with(v41(), 10, "2 8 1 8"), 28, "'$EndNodes' where node block 2 of 2 was expected");
}

TEST(GmshCheck, Nodes41Lines)
{
  expect_refused(with(v41(), 14, "3 1 1 0"), 14,
                 "a node tag line of a version 4.1 file has 1 number (the tag); found 4");
  expect_refused(with(v41(), 14, "9"), 14, "the node tag '9' is not an integer in the range 1..8 of the $Nodes header "
                                           "(line 10)");
  expect_refused(with(v41(), 24, "0 0"), 24, "a node coordinate line has 3 numbers (x y z); found 2");
  // Fewer coordinate lines than tag lines.
  expect_refused(without(v41(), 27, 27), 27, "'$EndNodes' where node coordinate line 8 of 8 was expected (the count "
                                             "is at line 11)");
  expect_refused(without(v41(), 20, 35), 9, "$Nodes is not ended by $EndNodes: the file ends at line 19, at node "
                                            "coordinate line 1 of 8");
}

TEST(GmshCheck, Elements41)
{
  auto l = v41();
  expect_refused(with(l, 30, "4"), 30, "the $Elements header of a version 4.1 file has 4 numbers (blocks, elements, "
                                       "smallest tag, largest tag); found 1: is this a version 2.2 file with a 4.1 "
                                       "header?");
  expect_refused(with(l, 30, "2 2 1 1"), 30, "declares 2 elements with tags 1..1: too few tags");
  expect_refused(with(l, 31, "2 1 3"), 31, "an element block header of a version 4.1 file has 4 numbers");
  expect_refused(with(l, 31, "7 1 3 1"), 31, "the entity dimension '7' is not an integer in 0..3");
  expect_refused(with(l, 33, "2 1 5 1"), 33, "an element block of type 5 (hexahedron), dimension 3, on an entity of "
                                             "dimension 2");
  expect_refused(with(l, 33, "3 1 5 2"), 33, "the element blocks hold more than the 2 elements");
  expect_refused(with(l, 34, "2 1 2 3 4 5 6 7"), 34, "an element line of type 5 (hexahedron) has 9 numbers (tag and 8 "
                                                     "nodes); found 8");
  expect_refused(with(l, 34, "3 1 2 3 4 5 6 7 8"), 34, "the element tag '3' is not an integer in the range 1..2 of the "
                                                       "$Elements header (line 30)");
  expect_refused(with(l, 30, "3 2 1 2"), 35, "'$EndElements' where element block 3 of 3 was expected");
  expect_refused(without(l, 35, 35), 29, "$Elements is not ended by $EndElements");
  expect_refused(with(with(l, 30, "2 3 1 3"), 33, "3 1 5 1"), 35,
                 "the 2 element blocks hold 2 elements; the $Elements header (line 30) declares 3");
}

TEST(GmshCheck, Entities41)
{
  auto l = v41();
  expect_refused(with(l, 5, "0 0 1"), 5, "the $Entities header has 4 numbers (points, curves, surfaces, volumes); "
                                         "found 3");
  expect_refused(with(l, 6, "1 0 0 0 1 1 0 2 3 4 4 1 2 3 4"), 6,
                 "surface 1 belongs to 2 physical groups: deal.II 9.4 reads at most one per entity");
  expect_refused(with(l, 6, "1 0 0 0 1 1 0 1 3 4 1 2 3"), 6, "a surface entity line is 'tag minx miny minz maxx maxy "
                                                             "maxz n-physical physical... n-bounding bounding...': 14 "
                                                             "numbers here; found 13");
  expect_refused(with(l, 6, "1 0 0 0 1 1e400 0 1 3 4 1 2 3 4"), 6, "'1e400' is not a finite number");
  expect_refused(with(l, 7, "1 0 0 0 1 1 1 x 1 1 1"), 7, "the number of physical tags 'x' is not an integer");
  expect_refused(with(l, 5, "0 0 2 1"), 8, "'$EndEntities' where volume entity 1 of 1 was expected");
  expect_refused(with(l, 5, "1 0 1 1"), 6, "a point entity line is 'tag x y z n-physical physical...': 6 numbers here; "
                                           "found 14");
  expect_refused(with(l, 5, "0 0 1 2"), 8, "'$EndEntities' where volume entity 2 of 2 was expected");
  // Points: tag x y z n-physical physical...
  EXPECT_EQ(message(with(inserting(l, 6, "1 0 0 0 1 7"), 5, "1 0 1 1")), "accepted");
}

// --- the meshes of the project ---

TEST(GmshCheck, ProjectMeshes)
{
  const auto prm = prm_folder();
  ASSERT_FALSE(prm.empty()) << "prm/ not found from " << std::filesystem::current_path();
  unsigned int n_files = 0;
  for (const auto &entry : std::filesystem::recursive_directory_iterator(prm))
    if (entry.path().extension() == ".msh")
      {
        std::ifstream in(entry.path());
        EXPECT_EQ(message(in), "accepted") << entry.path();
        ++n_files;
      }
  EXPECT_GE(n_files, 1u);
  // The pulled bar of two_bars_loads: 459 nodes, 200 hexahedra and 408 boundary quadrilaterals.
  std::ifstream in(prm / "verification/two_bars_loads/bar.msh");
  const auto    s = check_gmsh(in);
  EXPECT_DOUBLE_EQ(s.version, 2.2);
  EXPECT_EQ(s.n_nodes, 459u);
  EXPECT_EQ(s.n_hexahedra, 200u);
  EXPECT_EQ(s.n_elements, 608u);
}

TEST(GmshCheck, ProjectMeshInVersion41)
{
  // bar.msh rewritten as version 4.1 (one node block, one block per element type) passes with the same counts.
  const auto prm = prm_folder();
  ASSERT_FALSE(prm.empty());
  std::ifstream in(prm / "verification/two_bars_loads/bar.msh");
  std::string   line;
  Lines         nodes, quads, hexes;
  std::string   section;
  while (std::getline(in, line))
    {
      if (line[0] == '$')
        {
          section = line;
          continue;
        }
      std::istringstream f(line);
      std::vector<std::string> w;
      for (std::string x; f >> x;)
        w.push_back(x);
      if (section == "$Nodes" && w.size() == 4)
        nodes.push_back(line);
      else if (section == "$Elements" && w.size() > 1)
        {
          std::string out = w[0];
          for (std::size_t i = 3 + std::stoul(w[2]); i < w.size(); ++i)
            out += " " + w[i];
          (w[1] == "3" ? quads : hexes).push_back(out);
        }
    }
  Lines l = {"$MeshFormat", "4.1 0 8", "$EndMeshFormat", "$Nodes",
             "1 " + std::to_string(nodes.size()) + " 1 " + std::to_string(nodes.size()),
             "3 1 0 " + std::to_string(nodes.size())};
  for (const auto &n : nodes)
    l.push_back(n.substr(0, n.find(' ')));
  for (const auto &n : nodes)
    l.push_back(n.substr(n.find(' ') + 1));
  const auto n_elements = std::to_string(quads.size() + hexes.size());
  l.insert(l.end(), {"$EndNodes", "$Elements", "2 " + n_elements + " 1 " + n_elements,
                     "2 1 3 " + std::to_string(quads.size())});
  l.insert(l.end(), quads.begin(), quads.end());
  l.push_back("3 1 5 " + std::to_string(hexes.size()));
  l.insert(l.end(), hexes.begin(), hexes.end());
  l.push_back("$EndElements");
  const auto s = summary(join(l));
  EXPECT_EQ(s.n_nodes, 459u);
  EXPECT_EQ(s.n_hexahedra, 200u);
  EXPECT_EQ(s.n_elements, 608u);
}
