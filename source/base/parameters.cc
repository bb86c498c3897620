// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/base/parameters.h>

#include <algorithm>
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
    for (const char c : text)
      {
        if (c == '"' || c == '\\')
          out += '\\';
        if (c == '\n')
          {
            out += "\\n";
            continue;
          }
        out += c;
      }
    return out;
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

    /// Declared keys of @p prm, as "path/key".
    std::set<std::string>
    declared_keys(const dealii::ParameterHandler &prm)
    {
      std::ostringstream out;
      prm.print_parameters(out, dealii::ParameterHandler::PRM);
      std::set<std::string> keys;
      for (const auto &[path, line] : scan_prm(out.str()))
        keys.insert(path);
      return keys;
    }

    /// "Did you mean ...?" for an unknown key at @p line of @p text.
    std::string
    suggestion(const dealii::ParameterHandler &prm, const std::string &text, const int line,
               const std::string &key)
    {
      const auto  sections = sections_at_line(text, line);
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

    /// Turns deal.II's parse errors into one located line.
    [[noreturn]] void
    rethrow_parse_error(const dealii::ExceptionBase &e, const dealii::ParameterHandler &prm,
                        const std::string &text)
    {
      std::ostringstream info;
      e.print_info(info);
      std::string msg = info.str();
      // Collapse deal.II's multi-line layout to one line.
      msg = std::regex_replace(msg, std::regex("\\s*\\n\\s*"), " ");
      msg = trim(msg);
      std::smatch m;
      if (std::regex_search(msg, m, std::regex("Line <(\\d+)> of file <([^>]*)>:?\\s*(.*)")))
        {
          const int   line   = std::stoi(m[1]);
          std::string reason = m[3];
          std::smatch k;
          if (std::regex_search(reason, k, std::regex("No entry with name <([^>]*)> was declared")))
            reason = "unknown key '" + std::string(k[1]) + "'." +
                     suggestion(prm, text, line, k[1]);
          else if (std::regex_search(reason, k, std::regex("no such subsection to be entered: (.*)")))
            reason = "unknown subsection '" + trim(k[1]) + "'.";
          throw InputError(std::string(m[2]) + ":" + std::to_string(line) + ": " + reason);
        }
      throw InputError(msg);
    }
  } // namespace

  PrmSource::PrmSource(const std::string &filename)
    : filename_(filename)
  {
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
    const auto eq = assignment.find('=');
    if (eq == std::string::npos || assignment.find('/') == std::string::npos)
      throw InputError("--set '" + assignment +
                       "': expected the form \"Section/Subsection/key=value\".");
    overrides_.emplace_back(trim(assignment.substr(0, eq)), trim(assignment.substr(eq + 1)));
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
          rethrow_parse_error(e, prm, source.text());
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
