#!/usr/bin/python3
"""Converts a 24/32-bit TrueColor XWD file (Xvfb's -fbdir frame buffer) to PNG, stdlib only.

usage: xwd_to_png.py IN.xwd OUT.png
"""
import struct
import sys
import zlib

XWD_HEADER_FIELDS = 25  # CARD32 fields of XWDFileHeader, big-endian
XWD_COLOR_SIZE = 12     # bytes per colormap entry


def read_xwd(path, box=None):
    """Returns width, height, RGB rows; box = (x, y, w, h) decodes only that region."""
    data = open(path, "rb").read()
    h = struct.unpack(">%dI" % XWD_HEADER_FIELDS, data[:4 * XWD_HEADER_FIELDS])
    header_size, width, height = h[0], h[4], h[5]
    byte_order, bits_per_pixel, bytes_per_line = h[7], h[11], h[12]
    red_mask, green_mask, blue_mask, ncolors = h[14], h[15], h[16], h[19]
    if bits_per_pixel not in (24, 32):
        raise ValueError("unsupported bits per pixel %d" % bits_per_pixel)
    offset = header_size + ncolors * XWD_COLOR_SIZE
    step = bits_per_pixel // 8
    endian = "little" if byte_order == 0 else "big"

    def shift(mask):
        return (mask & -mask).bit_length() - 1

    rs, gs, bs = shift(red_mask), shift(green_mask), shift(blue_mask)
    x0, y0, x1, y1 = 0, 0, width, height
    if box is not None:
        x0, y0 = max(0, box[0]), max(0, box[1])
        x1, y1 = min(width, box[0] + box[2]), min(height, box[1] + box[3])
    rows = []
    for y in range(y0, y1):
        start = offset + y * bytes_per_line + x0 * step
        line = data[start: start + (x1 - x0) * step]
        row = bytearray((x1 - x0) * 3)
        for x in range(x1 - x0):
            p = int.from_bytes(line[x * step:(x + 1) * step], endian)
            row[3 * x] = (p & red_mask) >> rs
            row[3 * x + 1] = (p & green_mask) >> gs
            row[3 * x + 2] = (p & blue_mask) >> bs
        rows.append(bytes(row))
    return x1 - x0, y1 - y0, rows


def write_png(path, width, height, rows):
    def chunk(tag, payload):
        return (struct.pack(">I", len(payload)) + tag + payload +
                struct.pack(">I", zlib.crc32(tag + payload) & 0xFFFFFFFF))

    raw = b"".join(b"\x00" + r for r in rows)  # filter type 0 per row
    png = b"\x89PNG\r\n\x1a\n"
    png += chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0))
    png += chunk(b"IDAT", zlib.compress(raw, 6))
    png += chunk(b"IEND", b"")
    open(path, "wb").write(png)


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    w, h, r = read_xwd(sys.argv[1])
    write_png(sys.argv[2], w, h, r)
