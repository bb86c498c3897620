# SPDX-License-Identifier: LGPL-2.1-or-later
"""What the report scripts that write tables into doc/ share (standard library only):

- replace_marked(path, tag, lines, add=True): the text between <!-- TAG BEGIN --> and
  <!-- TAG END --> of the Markdown file becomes `lines`; with add, missing markers are appended
  first (and a missing file is created), without it a file lacking them is left alone;
- machine(): the CPU model from /proc/cpuinfo;
- commit_of(path): the short git commit of the checkout that holds `path`.
"""
import os
import re
import subprocess


def replace_marked(path, tag, lines, add=True):
    """Returns whether the file was written."""
    begin, end = f"<!-- {tag} BEGIN -->", f"<!-- {tag} END -->"
    text = open(path).read() if os.path.exists(path) else ""
    if begin not in text:
        if not add:
            return False
        text += ("\n" if text else "") + f"{begin}\n{end}\n"
    text = re.sub(re.escape(begin) + ".*" + re.escape(end), lambda _: begin + "\n" + "\n".join(lines) + "\n" + end,
                  text, flags=re.S)
    with open(path, "w") as f:
        f.write(text)
    return True


def machine():
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return "unknown CPU"


def commit_of(path):
    try:
        return subprocess.run(["git", "-C", os.path.dirname(os.path.abspath(path)), "rev-parse", "--short", "HEAD"],
                              capture_output=True, text=True).stdout.strip() or "unknown"
    except OSError:
        return "unknown"
