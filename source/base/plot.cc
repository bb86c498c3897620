// SPDX-License-Identifier: LGPL-2.1-or-later
#include <shard/base/plot.h>

#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>

namespace shard::base
{
  namespace
  {
    std::string
    shell_quote(const std::string &s)
    {
      std::string out = "'";
      for (const char c : s)
        out += c == '\'' ? std::string("'\\''") : std::string(1, c);
      return out + "'";
    }
  } // namespace

  std::string
  run_plot_script(const std::string &script, const std::vector<std::string> &arguments)
  {
#ifdef SHARD_SOURCE_DIR
    const std::string path = std::string(SHARD_SOURCE_DIR) + "/contrib/utilities/" + script;
#else
    const std::string path;
#endif
    const std::string python = "/usr/bin/python3";
    if (path.empty() || !std::filesystem::exists(path))
      return "no plot: the script '" + path + "' does not exist.";
    if (access(python.c_str(), X_OK) != 0)
      return "no plot: " + python + " is not available.";
    std::string command = python + " " + shell_quote(path);
    for (const auto &a : arguments)
      command += " " + shell_quote(a);
    command += " 2>&1";
    std::string output;
    int         status = -1;
    if (FILE *pipe = popen(command.c_str(), "r"))
      {
        char buffer[512];
        while (std::fgets(buffer, sizeof(buffer), pipe))
          output += buffer;
        status = pclose(pipe);
      }
    if (status == 0)
      return "";
    const int code = (status != -1 && WIFEXITED(status)) ? WEXITSTATUS(status) : -1;
    return "plotting failed (exit " + std::to_string(code) + "): " + command + "\n" + output;
  }
} // namespace shard::base
