#!/usr/bin/env python3
"""Copy a reference tile folder with another `reference_sigma_m` in its tile.bin header.

An experiment tool, not a product path: it rewrites the two f32 fields (x, y, metres) that
close the postcard header just before `height_noise_m` (docs/tile-format.md, format 5),
then the CRC-32. Used in docs/registration.md ("A floor under the 128 m map's σ",
session 46) to fly a descent with a different claimed map error without rebuilding the map.

    python3 tools/set_reference_sigma.py SRC_DIR DST_DIR SIGMA_M
"""
import shutil
import struct
import sys
import zlib

src, dst, sigma = sys.argv[1], sys.argv[2], float(sys.argv[3])
if not (0.0 <= sigma <= 10_000.0):
    sys.exit("SIGMA_M must lie in [0, 10 000] m (the tile format's range)")
shutil.copytree(src, dst)
path = f"{dst}/tile.bin"
blob = bytearray(open(path, "rb").read())
if blob[:8] != b"UMBRATIL" or struct.unpack_from("<H", blob, 8)[0] != 5:
    sys.exit(f"{path}: not a format-5 Umbra tile")
if zlib.crc32(bytes(blob[:-4])) != struct.unpack_from("<I", blob, len(blob) - 4)[0]:
    sys.exit(f"{path}: bad checksum before the change")
header_len = struct.unpack_from("<H", blob, 10)[0]
at = 20 + header_len - 12  # reference_sigma_m x, y, then height_noise_m, all f32
old = struct.unpack_from("<ff", blob, at)
struct.pack_into("<ff", blob, at, sigma, sigma)
struct.pack_into("<I", blob, len(blob) - 4, zlib.crc32(bytes(blob[:-4])))
open(path, "wb").write(blob)
print(f"{path}: reference_sigma_m {old[0]:.6g}, {old[1]:.6g} -> {sigma:.6g}, {sigma:.6g} m")
