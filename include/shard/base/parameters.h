// SPDX-License-Identifier: LGPL-2.1-or-later
/**
 * @file parameters.h
 * @brief Input checking for .prm files: where each key stands, clear error messages,
 *        and the staged declare/parse loop that supports named subsections.
 * @ingroup base
 */
#pragma once

#include <deal.II/base/parameter_handler.h>

#include <array>
#include <functional>
#include <map>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace shard::base
{
  /**
   * @brief An error in the user's input. The message is complete and ready to print,
   * e.g. `bar.prm:42: C - Materials/steel/density = -7850: must be > 0. Unit: kg/m^3.`
   */
  class InputError : public std::runtime_error
  {
  public:
    using std::runtime_error::runtime_error;
  };

  /**
   * @brief An error in the command line itself (a malformed `--set`): `shard` exits with 2,
   * as for any other command-line error, where an InputError exits with 1.
   */
  class CommandLineError : public InputError
  {
  public:
    using InputError::InputError;
  };

  /**
   * @brief The text of one .prm input and the command-line overrides, with the line of each key.
   *
   * The file is scanned once for `subsection`, `set` and `end` so that checks made after
   * parsing (monotone tables, cross-checks, files that do not exist) can name the file and
   * line of the offending key, as deal.II itself does for syntax and pattern errors.
   */
  class PrmSource
  {
  public:
    /// An empty source: every key has its default value.
    PrmSource() = default;

    /**
     * @brief Reads @p filename. Throws InputError if the file cannot be read.
     */
    explicit PrmSource(const std::string &filename);
    // (A directory is refused as well: it reads as an empty file on Linux.)

    /**
     * @brief Adds an override of the form `Section/Sub/key=value` (from `--set`).
     * Throws CommandLineError if the form is wrong: no '=', no section, an empty section or
     * key name, a control character (a newline would add statements to the scene) or a
     * trailing backslash (a continuation line) in it.
     */
    void
    add_override(const std::string &assignment);

    /// The file name (empty when there is no file).
    const std::string &
    filename() const
    {
      return filename_;
    }

    /// The directory of the file, with a trailing slash ("" when there is no file).
    std::string
    directory() const;

    /// The file text.
    const std::string &
    text() const
    {
      return text_;
    }

    /// The overrides written as .prm text with nested subsections.
    std::string
    overrides_as_prm() const;

    /**
     * @brief Where the key @p path (`Section/Sub/key`) was set: `file.prm:42`,
     * `--set` or `default`.
     */
    std::string
    locate(const std::string &path) const;

    /**
     * @brief Throws InputError naming where @p path was set, the key, its value and @p requirement.
     */
    [[noreturn]] void
    fail(const std::string &path,
         const std::string &value,
         const std::string &requirement) const;

  private:
    std::string                                      filename_;
    std::string                                      text_;
    std::map<std::string, unsigned int>              lines_;
    std::vector<std::pair<std::string, std::string>> overrides_;
  };

  /**
   * @brief A component that owns parameters: it declares them (possibly in stages, when
   * the names of its subsections are themselves parameters) and checks them after parsing.
   */
  class ParameterOwner
  {
  public:
    virtual ~ParameterOwner() = default;

    /**
     * @brief Declares the parameters known so far. Called repeatedly until no component
     * declares anything new; values parsed in earlier rounds are already bound.
     * @return true if anything new was declared.
     */
    virtual bool
    declare_parameters(dealii::ParameterHandler &prm) = 0;

    /**
     * @brief Checks the parsed values; throws InputError naming key, line and range.
     */
    virtual void
    check_parameters(const PrmSource &source) const = 0;

  protected:
    /// For an owner that declares all its keys in one round: true on the first call only.
    bool
    first_declaration()
    {
      if (declared_once_)
        return false;
      declared_once_ = true;
      return true;
    }

  private:
    bool declared_once_ = false;
  };

  /**
   * @brief Declares and parses the parameters of all @p owners from @p source.
   *
   * Rounds of declaration and lenient parsing run until nothing new is declared
   * (named subsections such as `C - Materials/steel` appear once their names are known);
   * then one strict parse rejects undeclared keys, and every owner checks its values.
   * deal.II's own errors (unknown key, value outside its pattern) are turned into
   * InputError with file and line.
   */
  void
  read_parameters(dealii::ParameterHandler           &prm,
                  const std::vector<ParameterOwner *> &owners,
                  const PrmSource                     &source);

  /**
   * @brief Parses a table "x0 y0; x1 y1; ..." of @p n_columns numbers per row.
   * Throws std::invalid_argument with a short reason on a malformed table.
   */
  std::vector<std::vector<double>>
  parse_table(const std::string &text, unsigned int n_columns);

  /**
   * @brief Parses the white-space separated numbers of @p text (every word must be a whole
   * number). Throws std::invalid_argument naming the first word that is not a number.
   */
  std::vector<double>
  parse_numbers(const std::string &text);

  /**
   * @brief Escapes @p text for a JSON string: quotes, backslashes and every control character
   * (as `\n`, `\t` or `\u00XX`); bytes that are not valid UTF-8 become U+FFFD, so the result
   * is always a valid JSON string body.
   */
  std::string
  json_escape(const std::string &text);

  /**
   * @brief @p text cut to @p max_length characters (then "...") with every byte outside
   * printable ASCII shown as `\xHH`: safe to print in a one-line message.
   */
  std::string
  printable(const std::string &text, std::size_t max_length);

  /**
   * @brief The reason of @p e in one printable line: for a deal.II exception the text after
   * "Additional information:" without the stack trace, for others what(); cut to 300 characters.
   */
  std::string
  exception_reason(const std::exception &e);

  /// Writes @p content to @p path through a temporary file and a rename (atomic on POSIX), so
  /// that a reader never sees a half-written file. Throws std::runtime_error if it cannot write.
  void
  write_file_atomically(const std::string &path, const std::string &content);

  /// Parses "a, b, c" into three finite doubles; throws std::invalid_argument otherwise.
  std::array<double, 3>
  parse_point(const std::string &text);

  /**
   * @brief Checks a comma-separated list of names (bodies, materials, conditions) set at
   * @p path: each name uses letters, digits, '_' and '-' only and appears once; an empty list
   * is rejected unless @p allow_empty. Throws InputError through @p source.
   */
  void
  check_names(const PrmSource &source, const std::string &path, const std::string &text,
              const std::vector<std::string> &names, bool allow_empty);

  /// Splits @p text at @p separator and trims white space; empty items are dropped.
  std::vector<std::string>
  split(const std::string &text, char separator);

  /// Trims white space on both ends.
  std::string
  trim(const std::string &text);
} // namespace shard::base
