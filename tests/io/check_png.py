"""Decodes the PNG files lfnet wrote with Python's zlib and numpy alone (no libpng, no
libdeflate) and compares their samples with the raw files beside them.

Usage: check_png.py DIR. For every DIR/NAME.png there is DIR/NAME.json ({"height", "width",
"channels", "bits"}) and DIR/NAME.raw (the samples, row-major, interleaved, 16-bit ones in the
machine's byte order). Prints one line per file and exits non-zero on any difference.
"""
import json
import pathlib
import struct
import sys
import zlib

import numpy as np

COLOUR_TYPES = {0: 1, 4: 2, 2: 3, 6: 4}  # PNG colour type -> channels


def unfilter(data, height, row, bpp):
    out = np.zeros((height, row), dtype=np.int64)
    prev = np.zeros(row, dtype=np.int64)
    at = 0
    for y in range(height):
        kind = data[at]
        line = np.frombuffer(data, dtype=np.uint8, count=row, offset=at + 1).astype(np.int64)
        at += row + 1
        cur = np.zeros(row, dtype=np.int64)
        for i in range(row):
            left = cur[i - bpp] if i >= bpp else 0
            up = prev[i]
            up_left = prev[i - bpp] if i >= bpp else 0
            if kind == 0:
                pred = 0
            elif kind == 1:
                pred = left
            elif kind == 2:
                pred = up
            elif kind == 3:
                pred = (left + up) // 2
            elif kind == 4:
                p = left + up - up_left
                pa, pb, pc = abs(p - left), abs(p - up), abs(p - up_left)
                pred = left if pa <= pb and pa <= pc else (up if pb <= pc else up_left)
            else:
                raise ValueError("filter type %d" % kind)
            cur[i] = (line[i] + pred) & 0xFF
        out[y] = cur
        prev = cur
    return out.astype(np.uint8)


def decode(path):
    data = path.read_bytes()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise ValueError("no PNG signature")
    at, idat, header, ended = 8, b"", None, False
    while at < len(data):
        (size,) = struct.unpack(">I", data[at:at + 4])
        kind, body = data[at + 4:at + 8], data[at + 8:at + 8 + size]
        (crc,) = struct.unpack(">I", data[at + 8 + size:at + 12 + size])
        if zlib.crc32(kind + body) != crc:
            raise ValueError("bad CRC in %s" % kind)
        if kind == b"IHDR":
            header = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat += body
        elif kind == b"IEND":
            ended = True
        at += 12 + size
    if header is None or not ended:
        raise ValueError("missing IHDR or IEND")
    width, height, bits, colour, compression, filtering, interlace = header
    if compression or filtering or interlace:
        raise ValueError("unexpected IHDR %r" % (header,))
    channels = COLOUR_TYPES[colour]
    bpp = channels * bits // 8
    raw = unfilter(zlib.decompress(idat), height, width * bpp, bpp)
    if bits == 16:
        samples = raw.reshape(height, width * channels, 2).astype(np.uint16)
        samples = (samples[..., 0] << 8) | samples[..., 1]
    else:
        samples = raw
    return samples.reshape(height, width, channels), bits


def main():
    folder = pathlib.Path(sys.argv[1])
    bad = 0
    for png in sorted(folder.glob("*.png")):
        meta = json.loads(png.with_suffix(".json").read_text())
        dtype = np.uint16 if meta["bits"] == 16 else np.uint8
        want = np.fromfile(png.with_suffix(".raw"), dtype=dtype).reshape(
            meta["height"], meta["width"], meta["channels"])
        try:
            got, bits = decode(png)
            same = bits == meta["bits"] and got.shape == want.shape and np.array_equal(got, want)
            print("%s: %s" % (png.name, "equal" if same else "DIFFERENT"))
        except ValueError as e:
            same = False
            print("%s: %s" % (png.name, e))
        bad += not same
    sys.exit(1 if bad else 0)


main()
