# SPDX-License-Identifier: LGPL-2.1-or-later
"""Readers of what `shard run` writes, shared by the contrib/utilities scripts (standard library
only, so that scripts without numpy can use them):

- read_vtu(path): Points and named DataArrays of one .vtu piece, ASCII or deal.II binary (base64
  header of block sizes, zlib blocks), as {name: (values, components)} with values a flat list;
- last_pieces(out, stem): the .vtu pieces (one per rank) of the last record stem_NNNN;
- last_fragments(path): the time of the last output in fragments.csv and its rows.
"""
import base64
import csv
import glob
import os
import re
import struct
import zlib

FORMATS = {"Float32": "f", "Float64": "d", "Int32": "i", "UInt8": "B", "Int64": "q", "UInt32": "I", "UInt64": "Q"}


def decode(text, code):
    """A deal.II binary DataArray: base64 header (nblocks, block size, last size, compressed sizes)
    followed by the base64 zlib blocks; code is the struct format of one value."""
    text = text.strip()
    n = struct.unpack("<I", base64.b64decode(text[:8])[:4])[0]
    header_chars = 4 * ((4 * (3 + n) + 2) // 3)
    header = struct.unpack(f"<{3 + n}I", base64.b64decode(text[:header_chars]))
    data = base64.b64decode(text[header_chars:])
    raw, pos = b"", 0
    for size in header[3:]:
        raw += zlib.decompress(data[pos:pos + size])
        pos += size
    return list(struct.unpack(f"<{len(raw) // struct.calcsize(code)}{code}", raw))


def read_vtu(path):
    """{name: (flat list of values, number of components)} of one .vtu piece; the point
    coordinates are 'Points'."""
    with open(path) as f:
        xml = f.read()
    arrays = {}
    for m in re.finditer(r'<DataArray([^>]*)>(.*?)</DataArray>', xml, re.S):
        attrs, body = m.group(1), m.group(2)
        name = re.search(r'Name="([^"]*)"', attrs)
        name = name.group(1) if name else "Points"
        if 'format="binary"' in attrs:
            values = decode(body, FORMATS[re.search(r'type="([^"]*)"', attrs).group(1)])
        else:
            values = [float(x) for x in body.split()]
        ncomp = re.search(r'NumberOfComponents="(\d+)"', attrs)
        arrays[name] = (values, int(ncomp.group(1)) if ncomp else 1)
    return arrays


def last_pieces(out, stem):
    """The pieces stem_NNNN.R.vtu of the largest NNNN, sorted by rank R ([] if none)."""
    files = glob.glob(os.path.join(out, f"{stem}_[0-9][0-9][0-9][0-9].*.vtu"))
    if not files:
        return []
    last = max(int(re.search(rf"{stem}_(\d+)\.", os.path.basename(f)).group(1)) for f in files)
    return sorted(f for f in files if os.path.basename(f).startswith(f"{stem}_{last:04d}."))


def last_fragments(path):
    """(time, rows) of the last output in fragments.csv; (None, []) for an empty file."""
    with open(path) as f:
        rows = list(csv.DictReader(f))
    if not rows:
        return None, []
    t = max(float(r["time"]) for r in rows)
    return t, [r for r in rows if float(r["time"]) == t]
