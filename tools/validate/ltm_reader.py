#!/usr/bin/env python3
"""Independent reader for wavelet-mode `.ltm` files, written from docs/FORMAT.md alone.

This file was written only from the specification in docs/FORMAT.md (no Rust source
was consulted). It checks that the specification is complete: it decodes a `.ltm`
file of mode 2d, 4d or adaptive to the dense transport matrix exactly as
`ltm export` writes it (float32, shape (P, M, C), or (P, M) when C = 1).
`pca` files (mode 3) are refused. Format versions 1 to 10 are read (version 7 stores
side chunks and the column table as zstd frames: pip `zstandard`; version 8 may
store SURF and COLS as zstd frames of their planes), with column encodings 0 to 6
(encoding 6 starts its contexts from the PRIO chunk's states); a version-5 file's column norms (chunk NORM) are checked against
the decoded columns; the row layout (chunk SURF) and a version-6 file's receiving
mesh (chunk MESH) are decoded and checked, and a version-10 file's near-field rows
(chunk NEAR) are decoded and checked. Given a raw transport store (magic
LTMRAW) instead, it reads its header (versions 1 to 6; version 5 is one part of a
sharded bake, with its row range; version 6 adds a light plane), its surface records
and its receiving mesh (version 4, or versions 5 and 6 with flag bit 2), and prints
them; the matrix itself is not read.

Usage:
    python3 tools/validate/ltm_reader.py FILE.ltm [--compare EXPORT.npy] [--out OUT.npy] [--f64]
        [--mesh-json MESH.json]
    python3 tools/validate/ltm_reader.py FILE.raw [--mesh-json MESH.json]

--mesh-json writes the receiving mesh (or null) as JSON: "size" (the texture side S),
"positions", "normals", "uvs" (the f32 values as their IEEE-754 bit patterns, u32)
and "triangles".

Prints the shape, the format version and the number of columns of each
encoding; with --compare, the max abs difference and the relative L2
difference against an `ltm export` of the same file, and exits with status 1 if
the relative L2 difference exceeds 1e-5 (status 2 for a file it refuses).

By default the dequantization and inverse transforms run in float32, in the
operation order FORMAT.md gives, which reproduces `ltm export` bit for bit on
every test file (tools/validate/README.md); --f64 computes in float64
(differences of float32 rounding only).

Stages (one function each):
  read_container      header, chunk directory, CRCs
  parse_meta          META chunk
  parse_empty_rows    EMPT chunk
  parse_norms         NORM chunk (checked against the decoded columns: column_norm)
  parse_priors        PRIO chunk (encoding 6's starting context states)
  parse_surf          SURF chunk (row layout and surface records)
  parse_mesh          MESH chunk / the raw store's mesh region (receiver mesh)
  read_raw_store      a raw store's header, surface records and mesh
  parse_column_table  COLS chunk
  unplane             a version-8 chunk stored in planes (packing 2)
  decode_payload_plain / decode_payload_range / decode_payload_range4 / decode_payload_range5
                      column payload (encodings 1-2 / 3 / 4 / 5 and 6) -> sparse column
  RangeDecoder        "The binary coder" and encoding 4's 17-symbol contexts
  RawBitReader        encoding 4's raw bit stream
  walk_column         bands, blocks and significance bits (encodings 3 and 4)
  Values3 / Values4   values of a kept pixel, encoding 3 / encoding 4
  decode_range_stream / decode_range_stream4    the walk with those values
  dequantize_column   scale codes, u = q*s/Q, division by the band weights
  band_weights        per-band synthesis norms
  inverse_2d / inverse_1d_*                     inverse column and row transforms
  decode_matrix       the whole pipeline
Only numpy, the standard library and (for encoding 2) `zstandard` are used.
"""

import argparse
import math
import struct
import sys
import zlib

import numpy as np

MAGIC = b"\x89LTM\r\n\x1a\n"

# PyWavelets' dec_lo (FORMAT.md "Wavelets": "lo is PyWavelets' dec_lo").
DEC_LO = {
    0: [0.7071067811865476, 0.7071067811865476],  # haar
    1: [-0.12940952255126037, 0.22414386804185735, 0.836516303737469,
        0.48296291314469025],  # d4 = db2
    2: [0.035226291882100656, -0.08544127388224149, -0.13501102001039084,
        0.4598775021193313, 0.8068915093133388, 0.3326705529509569],  # d6 = db3
    3: [-0.010597401784997278, 0.032883011666982945, 0.030841381835986965,
        -0.18703481171888114, -0.02798376941698385, 0.6308807679295904,
        0.7148465705525415, 0.23037781330885523],  # d8 = db4
}
FILTER_NAMES = {0: "haar", 1: "d4", 2: "d6", 3: "d8", 4: "legall53", 5: "cdf97"}

# Lifting filters: list of (kind, constant) in forward order, and the final scales.
CDF97_K = float(np.float32(1.230174104914001))
LIFTING = {
    4: ([("predict", -0.5), ("update", 0.25)], 1.0, 1.0),
    5: ([("predict", float(np.float32(-1.586134342059924))),
         ("update", float(np.float32(-0.052980118572961))),
         ("predict", float(np.float32(0.882911075530934))),
         ("update", float(np.float32(0.443506852043971)))],
        1.0 / CDF97_K, CDF97_K),  # forward: low *= 1/K, high *= K
}


class FormatError(Exception):
    pass


def crc32(b):
    return zlib.crc32(b) & 0xFFFFFFFF


# ----------------------------------------------------------------------------
# Container


def read_container(buf):
    """Validate the header and chunk directory; return {tag: bytes}, version, features."""
    if len(buf) < 28 or buf[:8] != MAGIC:
        raise FormatError("not an .ltm file (bad magic)")
    version, features, k, reserved = struct.unpack_from("<4I", buf, 8)
    if version not in (1, 2, 3, 4, 5, 6, 7, 8, 9, 10):
        raise FormatError(f"unsupported format version {version}")
    if reserved != 0:
        raise FormatError("reserved header field is not 0")
    if features & ~127:
        raise FormatError(f"unknown feature bits {features:#x}")
    if version == 1 and features & ~1:
        raise FormatError("feature bits 1/2 in a version-1 file")
    if version < 5 and features & 8:
        raise FormatError(f"feature bit 3 in a version-{version} file")
    if version < 6 and features & 16:
        raise FormatError(f"feature bit 4 in a version-{version} file")
    if version < 9 and features & 32:
        raise FormatError(f"feature bit 5 in a version-{version} file")
    if version < 10 and features & 64:
        raise FormatError(f"feature bit 6 in a version-{version} file")
    if features & 64 and not features & 4:
        raise FormatError("feature bit 6 (NEAR) without bit 2 (SURF)")
    if not 3 <= k <= {1: 4, 5: 8, 6: 9, 7: 9, 8: 9, 9: 10, 10: 11}.get(version, 7):
        raise FormatError(f"bad chunk count {k}")
    end = 24 + 32 * k
    if len(buf) < end + 4:
        raise FormatError("truncated directory")
    stored_crc, = struct.unpack_from("<I", buf, end)
    if crc32(buf[:end]) != stored_crc:
        raise FormatError("header/directory CRC mismatch")
    chunks, last_end = {}, end + 4
    for e in range(k):
        base = 24 + 32 * e
        tag = bytes(buf[base:base + 4])
        enc, off, ln, ccrc, unpacked = struct.unpack_from("<IQQII", buf, base + 4)
        if version < 7:
            enc, unpacked = 0, 0
        if (enc, unpacked == 0) != (0, True) and not (
                enc == 1 and unpacked > 0 and tag in (b"ALBD", b"EMPT", b"SURF", b"MESH", b"NEAR", b"COLS", b"PRIO")) \
                and not (enc == 2 and version >= 8 and unpacked > 0 and tag in (b"SURF", b"COLS")):
            raise FormatError(f"chunk {tag!r}: encoding {enc} with unpacked length {unpacked}")
        if tag in chunks:
            raise FormatError(f"duplicate chunk {tag!r}")
        if off < last_end or off + ln > len(buf):
            raise FormatError(f"chunk {tag!r} overlaps or lies outside the file")
        last_end = off + ln
        data = buf[off:off + ln]
        if tag != b"DATA" and crc32(data) != ccrc:
            raise FormatError(f"chunk {tag!r} CRC mismatch")
        if enc in (1, 2):
            import zstandard
            data = zstandard.ZstdDecompressor().decompress(bytes(data), max_output_size=unpacked)
            if len(data) != unpacked:
                raise FormatError(f"chunk {tag!r} unpacks to {len(data)} bytes, not {unpacked}")
            if enc == 2:
                data = unplane(data)
        chunks[tag] = data
    want = {b"META"}
    if features & 1:
        want.add(b"ALBD")
    if features & 2:
        want.add(b"EMPT")
    if features & 4:
        want.add(b"SURF")
    if features & 8:
        want.add(b"NORM")
    if features & 16:
        want.add(b"MESH")
    if features & 32:
        want.add(b"PRIO")
    if features & 64:
        want.add(b"NEAR")
    if b"PCAM" in chunks or b"PCAB" in chunks or b"PCAC" in chunks:
        raise FormatError("this is a pca file (mode 3): not supported by this reader")
    want |= {b"COLS", b"DATA"}
    if set(chunks) != want:
        raise FormatError(f"chunks {sorted(chunks)} do not match feature bits {features}")
    return chunks, version, features


def unplane(planar):
    """FORMAT.md "Planes": the head as is, then per word w and byte b the plane of
    byte b of each record's delta of word w; undone by summing the deltas mod 2^32."""
    L = len(planar)
    h, N = L % 28, L // 28
    out = bytearray(planar[:h])
    words = np.zeros((N, 7), np.uint32)
    for w in range(7):
        delta = np.zeros(N, np.uint32)
        for b in range(4):
            start = h + (4 * w + b) * N
            delta |= np.frombuffer(planar, np.uint8, N, start).astype(np.uint32) << np.uint32(8 * b)
        words[:, w] = np.cumsum(delta, dtype=np.uint64).astype(np.uint32)  # mod 2^32
    out += words.astype("<u4").tobytes()
    return bytes(out)


def parse_meta(meta):
    if len(meta) != 64:
        raise FormatError("META is not 64 bytes")
    W, H, n, C = struct.unpack_from("<4I", meta, 0)
    mode, row_filter, col_filter, bits = meta[16], meta[17], meta[18], meta[19]
    seed, = struct.unpack_from("<Q", meta, 20)
    target, measured, keep = struct.unpack_from("<ffI", meta, 28)
    norm, = struct.unpack_from("<d", meta, 40)
    if mode == 3:
        raise FormatError("this is a pca file (mode 3): not supported by this reader")
    if mode not in (0, 1, 2):
        raise FormatError(f"bad mode {mode}")
    if not (1 <= W <= 32768 and 1 <= H <= 32768 and W * H <= 1 << 26):
        raise FormatError("bad image size")
    if not (1 <= n <= 1024 and n & (n - 1) == 0):
        raise FormatError("bad face resolution")
    if C not in (1, 3):
        raise FormatError("bad channel count")
    if row_filter not in (0, 1, 2, 3):
        raise FormatError("row filter must be orthonormal (0..3)")
    if col_filter not in FILTER_NAMES:
        raise FormatError("bad column filter")
    if not 2 <= bits <= 16:
        raise FormatError("bad bits")
    return dict(W=W, H=H, n=n, C=C, mode=mode, row_filter=row_filter,
                col_filter=col_filter, bits=bits, seed=seed, target=target,
                measured=measured, keep=keep, norm=norm)


def parse_surf(surf, W, H):
    """FORMAT.md "In the .ltm container": layout, parameterization, row count, reserved,
    then 28-byte records. Returns (layout, parameterization); checks every record."""
    if len(surf) < 16:
        raise FormatError("SURF is shorter than its header")
    layout, param, rows, reserved = struct.unpack_from("<4I", surf, 0)
    if layout not in (0, 1) or reserved != 0 or rows != W * H:
        raise FormatError(f"SURF header {layout, param, rows, reserved} is invalid")
    if layout == 0 and param != 0 or layout == 1 and (param not in (1, 2, 3) or W != H):
        raise FormatError(f"SURF layout {layout} with parameterization {param}, {W}x{H}")
    if len(surf) != 16 + 28 * rows:
        raise FormatError("SURF has the wrong length")
    check_surface_records(surf[16:], rows)
    return layout, param


def check_surface_records(b, rows):
    rec = np.frombuffer(b, "<f4", 7 * rows).reshape(rows, 7)
    flags = np.frombuffer(b, "<u4", 7 * rows).reshape(rows, 7)[:, 6]
    if (flags > 1).any():
        raise FormatError("a surface record's flags are not 0 or 1")
    valid = flags == 1
    if rec[~valid, :6].any():
        raise FormatError("an invalid surface record is not all zero")
    v = rec[valid, :6].astype(np.float64)
    if not np.isfinite(v).all() or (np.abs(np.linalg.norm(v[:, 3:], axis=1) - 1) > 1e-3).any():
        raise FormatError("a valid surface record is not finite or its normal not unit")


def parse_mesh(b, S):
    """FORMAT.md "Receiver mesh": V, T, two reserved 0 (u32), then V positions
    (f32 x3), V normals (f32 x3), V texture coordinates (f32 x2), T triangles (u32 x3)."""
    if len(b) < 16:
        raise FormatError("the mesh is shorter than its 16-byte header")
    V, T, r0, r1 = struct.unpack_from("<4I", b, 0)
    if V > 1 << 26 or T > 1 << 26 or r0 or r1:
        raise FormatError(f"mesh header {V, T, r0, r1} is invalid")
    if len(b) != 16 + 32 * V + 12 * T:
        raise FormatError(f"mesh of {len(b)} bytes for {V} vertices and {T} triangles")
    pos = np.frombuffer(b, "<f4", 3 * V, 16).reshape(V, 3)
    nrm = np.frombuffer(b, "<f4", 3 * V, 16 + 12 * V).reshape(V, 3)
    uv = np.frombuffer(b, "<f4", 2 * V, 16 + 24 * V).reshape(V, 2)
    tri = np.frombuffer(b, "<u4", 3 * T, 16 + 32 * V).reshape(T, 3)
    length = np.sqrt((nrm * nrm).sum(axis=1, dtype=np.float32))
    if T == 0 or not np.isfinite(pos).all() or (tri >= V).any():
        raise FormatError("mesh without triangles, with a non-finite position or a bad index")
    if not ((length == 0) | (np.abs(length - 1) <= 1e-3)).all():
        raise FormatError("a mesh normal is neither zero nor of unit length")
    if not ((uv >= 0) & (uv <= S)).all():
        raise FormatError(f"a mesh texture coordinate lies outside [0, {S}]")
    return dict(size=S, positions=pos, normals=nrm, uvs=uv, triangles=tri)


RAW_MAGIC = b"LTMRAW\0\x01"


def parse_plane(b):
    """FORMAT.md "Near-field rows": the 88-byte plane record, checked."""
    order, reserved, side = struct.unpack_from("<IId", b, 0)
    origin, x, y = (struct.unpack_from("<3d", b, 16 + 24 * i) for i in range(3))
    finite = all(math.isfinite(v) for v in (side, *origin, *x, *y))
    dot = lambda a, c: sum(u * v for u, v in zip(a, c))
    if (reserved or not finite or order == 0 or order & (order - 1) or order > 256
            or not 0 < side <= 1000 or abs(dot(x, x) - 1) > 1e-9 or abs(dot(y, y) - 1) > 1e-9
            or abs(dot(x, y)) > 1e-9):
        raise FormatError("bad light plane record")
    return dict(order=order, side=side, origin=origin, x=x, y=y)


def parse_near(b, P, C):
    """FORMAT.md "Near-field rows", chunk NEAR: the plane and, per row and
    channel, the (index, value) lists of its nonzero Haar coefficients."""
    if len(b) < 96:
        raise FormatError("NEAR truncated")
    channels, reserved = struct.unpack_from("<II", b, 0)
    if channels != C or reserved:
        raise FormatError("NEAR channels or reserved field is wrong")
    plane = parse_plane(b[8:96])
    n2 = plane["order"] ** 2
    if len(b) < 96 + 4 * P * C:
        raise FormatError("NEAR truncated")
    counts = np.frombuffer(bytes(b[96:96 + 4 * P * C]), "<u4")
    if counts.size and counts.max() > n2:
        raise FormatError("NEAR entry count past order^2")
    E = int(counts.sum())
    at = 96 + 4 * P * C
    idx = np.frombuffer(bytes(b[at:at + 2 * E]), "<u2")
    at = -(-(at + 2 * E) // 4) * 4
    val = np.frombuffer(bytes(b[at:at + 4 * E]), "<f4")
    if idx.size != E or val.size != E or len(b) != at + 4 * E:
        raise FormatError("NEAR length is wrong")
    if E and (idx.max() >= n2 or not np.all(np.isfinite(val)) or np.any(val == 0)):
        raise FormatError("NEAR index or value out of range")
    starts = np.concatenate([[0], np.cumsum(counts, dtype=np.int64)])
    rows = []
    for i in range(P * C):
        k = idx[starts[i]:starts[i + 1]]
        if k.size > 1 and np.any(np.diff(k.astype(np.int64)) <= 0):
            raise FormatError("NEAR indices do not increase")
        rows.append((k, val[starts[i]:starts[i + 1]]))
    return plane, rows


def near_json(near):
    """The near-field rows as plain JSON: the plane (f64 as their IEEE-754 bits,
    u64) and, per row and channel, [indices, value bits (u32)]."""
    if near is None:
        return None
    plane, rows = near
    bits = lambda v: struct.unpack("<Q", struct.pack("<d", v))[0]
    return dict(order=plane["order"], side=bits(plane["side"]),
                origin=[bits(v) for v in plane["origin"]], x=[bits(v) for v in plane["x"]],
                y=[bits(v) for v in plane["y"]],
                rows=[[k.tolist(), v.view("<u4").tolist()] for k, v in rows])


def read_raw_store(buf):
    """FORMAT.md "Raw transport store": the header of any version (1 to 5), the
    surface records (versions 3 to 5) and the receiving mesh (version 4, or 5 with
    flag bit 2). Returns a dict of the header fields, with "mesh" (parse_mesh's dict,
    or None) and, for a version-5 part, "rows" = (first_row, first_row + row_count)."""
    if buf[:8] != RAW_MAGIC or len(buf) < 64:
        raise FormatError("not a raw store")
    version, flags, W, H, n, C, block_rows, block_count = struct.unpack_from("<8I", buf, 8)
    hlen = {1: 64, 2: 96, 3: 112, 4: 128, 5: 144, 6: 240}.get(version)
    if hlen is None or len(buf) < hlen:
        raise FormatError(f"raw store version {version} or truncated header")
    if crc32(buf[:hlen - 4]) != struct.unpack_from("<I", buf, hlen - 4)[0]:
        raise FormatError("raw store header CRC mismatch")
    allowed = {1: 1, 2: 1, 3: 3, 4: 7, 5: 15, 6: 23}[version]
    has_mesh = bool(flags & 4)
    if (flags & ~allowed or bool(flags & 2) != (version >= 3)
            or (version == 4 and not has_mesh) or bool(flags & 8) != (version == 5)
            or bool(flags & 16) != (version == 6)):
        raise FormatError(f"raw store flags {flags:#x} in version {version}")
    data_offset, albedo_offset, reserved = struct.unpack_from("<QQI", buf, 40)
    if reserved:
        raise FormatError("raw store reserved field is not 0")
    P = W * H
    rows = (0, P)
    if version == 5:
        first, count = struct.unpack_from("<QQ", buf, 124)
        if count == 0 or first + count > P:
            raise FormatError(f"raw store part rows {first}+{count} outside 0..{P}")
        rows = (first, first + count)
    R = rows[1] - rows[0]  # rows stored: the table, flags, albedo and data cover them
    if block_rows == 0 or block_rows > P or block_count != -(-R // block_rows):
        raise FormatError("raw store block_rows or block_count is wrong")
    end = hlen + 8 * block_count + R  # flags_offset + R
    if flags & 1:
        end = -(-end // 64) * 64 + 12 * R
    out = dict(version=version, W=W, H=H, n=n, C=C, data_offset=data_offset, mesh=None,
               rows=rows)
    if version >= 3:
        surface_offset, layout, param = struct.unpack_from("<QII", buf, 92)
        if surface_offset != -(-end // 64) * 64 or layout not in (0, 1):
            raise FormatError("raw store surface_offset or row layout is wrong")
        recs = buf[surface_offset:surface_offset + 28 * P + 4]
        if len(recs) != 28 * P + 4 or crc32(recs[:-4]) != struct.unpack("<I", recs[-4:])[0]:
            raise FormatError("raw store surface records truncated or CRC mismatch")
        check_surface_records(recs[:-4], P)
        end = surface_offset + 28 * P + 4
        out.update(layout=layout, parameterization=param)
    if version >= 5 and not has_mesh and struct.unpack_from("<QQ", buf, 108) != (0, 0):
        raise FormatError("raw store mesh_offset or mesh_len is not 0 without a mesh")
    if has_mesh:
        mesh_offset, mesh_len = struct.unpack_from("<QQ", buf, 108)
        if layout != 1 or W != H or mesh_offset != -(-end // 64) * 64:
            raise FormatError("raw store mesh_offset or a mesh's row layout is wrong")
        region = buf[mesh_offset:mesh_offset + mesh_len + 4]
        if len(region) != mesh_len + 4 or crc32(region[:-4]) != struct.unpack("<I", region[-4:])[0]:
            raise FormatError("raw store mesh truncated or CRC mismatch")
        out["mesh"] = parse_mesh(region[:-4], W)
        end = mesh_offset + mesh_len + 4
    data_end = data_offset + 4 * R * 6 * n * n * C
    if version == 6:
        if struct.unpack_from("<QQ", buf, 124) != (0, 0):
            raise FormatError("raw store bytes 124..140 are not 0 in version 6")
        plane_offset, = struct.unpack_from("<Q", buf, 140)
        out["plane"] = parse_plane(buf[148:236])
        if plane_offset != -(-data_end // 4096) * 4096:
            raise FormatError("raw store plane_offset is wrong")
        data_end = plane_offset + 4 * R * out["plane"]["order"] ** 2 * C
    if data_offset != -(-end // 4096) * 4096 or len(buf) != data_end:
        raise FormatError("raw store data_offset or file length is wrong")
    return out


def mesh_json(mesh):
    if mesh is None:
        return None
    bits = lambda a: a.view("<u4").tolist()  # noqa: E731
    return dict(size=mesh["size"], positions=bits(mesh["positions"]),
                normals=bits(mesh["normals"]), uvs=bits(mesh["uvs"]),
                triangles=mesh["triangles"].tolist())


def parse_empty_rows(empt, P):
    if len(empt) != (P + 7) // 8:
        raise FormatError("EMPT has the wrong length")
    bits = np.unpackbits(np.frombuffer(empt, np.uint8), bitorder="little")
    if bits[P:].any():
        raise FormatError("EMPT bits past the last row are set")
    return bits[:P].astype(bool)


def parse_norms(norm, M):
    if len(norm) != 4 * M:
        raise FormatError("NORM has the wrong length")
    norms = np.frombuffer(norm, "<f4")
    if not (np.isfinite(norms) & (norms >= 0)).all():
        raise FormatError("NORM holds a value that is not finite and >= 0")
    return norms


def column_norm(codes, positions, values, W, H, d, C, B, dt):
    """FORMAT.md "NORM": sqrt of the running f64 sum of the squared u = q*s/Q,
    position by position, channel by channel, rounded to f32."""
    Q = (1 << (B - 1)) - 1
    s = scales_from_codes(codes, dt)
    g = group_map(W, H, d)[positions]
    u = (values.astype(dt) * s[g] / dt(Q)).astype(np.float64).ravel()
    total = np.cumsum(u * u)[-1] if len(u) else 0.0  # sequential, as one running sum
    return np.float32(np.sqrt(total))


def full_depth(W, H):
    m = max(W, H)
    return (m - 1).bit_length()  # ceil(log2(m)), 0 for m = 1


def parse_priors(b):
    """FORMAT.md "Encoding 6": the PRIO chunk's starting states, as
    (SP, SN) for `same` and `zero`, (P, N) for the walk's binary contexts in
    encoding 4's flat layout, and (CUM, NS) for the 80 symbol contexts."""
    if len(b) != 3732:
        raise FormatError(f"PRIO has {len(b)} bytes, not 3732")
    u = struct.unpack_from("<1866H", b, 0)
    if u[0] != 252 or u[1] != 80:
        raise FormatError(f"PRIO counts {u[0]}, {u[1]} (not 252, 80)")
    p, n = list(u[2:2 + 504:2]), list(u[3:2 + 504:2])
    if any(not 31 <= x <= 32737 for x in p) or any(x > 32 for x in n):
        raise FormatError("PRIO holds a binary state no context reaches")
    cum, ns = [], []
    for c in range(80):
        s = u[506 + 17 * c:506 + 17 * c + 17]
        a, cn = s[:16], s[16]
        if any(a[i] > a[i + 1] for i in range(15)) or a[15] > 32751 or cn > 32:
            raise FormatError("PRIO holds a symbol state no context reaches")
        cum.append([0] + [i + 1 + a[i] for i in range(16)] + [32768])
        ns.append(cn)
    # same, zero, then encoding 4's block, sig, sign, top, second (CTX4 layout).
    assert 250 == CTX4_TOTAL
    return dict(SP=p[:2], SN=n[:2], P=p[2:], N=n[2:], CUM=cum, NS=ns)


def parse_column_table(cols, M, P, W, H, version):
    if len(cols) != 28 * M:
        raise FormatError("COLS has the wrong length")
    table = []
    for j in range(M):
        off, slen, ulen, k, ccrc, d, enc, z = struct.unpack_from("<QIIIIBBH", cols, 28 * j)
        if (z != 0 or k > P or d > full_depth(W, H)
                or (enc == 3 and version < 3) or (enc == 4 and version < 4)
                or enc > 6 or (enc == 5 and version < 8) or (enc == 6 and version < 9)):
            raise FormatError(f"bad column table entry {j}")
        table.append(dict(off=off, slen=slen, ulen=ulen, k=k, crc=ccrc, d=d, enc=enc))
    return table


# ----------------------------------------------------------------------------
# Geometry: band sizes and bands


def band_size(W, H, l):
    for _ in range(l):
        W, H = (W + 1) // 2, (H + 1) // 2
    return W, H


def bands(W, H, d):
    """Bands in coding order: (x0, x1, y0, y1, group, orientation).

    Orientation 0 = low band, 1 = high x low y, 2 = low x high y, 3 = high x high y.
    Empty bands are included (callers skip them)."""
    bw_d, bh_d = band_size(W, H, d)
    out = [(0, bw_d, 0, bh_d, 0, 0)]
    for k in range(d, 0, -1):
        bw, bh = band_size(W, H, k)
        pw, ph = band_size(W, H, k - 1)
        out.append((bw, pw, 0, bh, k, 1))
        out.append((0, bw, bh, ph, k, 2))
        out.append((bw, pw, bh, ph, k, 3))
    return out


def group_map(W, H, d):
    """Scale group of every position i = y*W + x of the column image at depth d."""
    g = np.zeros((H, W), np.int64)
    for x0, x1, y0, y1, grp, _o in bands(W, H, d):
        g[y0:y1, x0:x1] = grp
    return g.reshape(-1)


# ----------------------------------------------------------------------------
# Varints


def read_varint(b, pos):
    v, shift = 0, 0
    while True:
        if pos >= len(b):
            raise FormatError("truncated varint")
        byte = b[pos]
        pos += 1
        v |= (byte & 0x7F) << shift
        shift += 7
        if byte < 0x80:
            return v, pos
        if shift >= 35:
            raise FormatError("varint too long")


# ----------------------------------------------------------------------------
# Column payloads, encodings 1 and 2


def decode_payload_plain(payload, d, C, k, Q):
    """Return (scale codes (d+1, C), positions (k,), values (k, C))."""
    ns = (d + 1) * C
    codes = np.frombuffer(payload, "<u2", ns, 0).reshape(d + 1, C)
    pos = 2 * ns
    positions = np.empty(k, np.int64)
    prev = -1
    for i in range(k):
        gap, pos = read_varint(payload, pos)
        prev = prev + gap + 1
        positions[i] = prev
    vals = np.empty(k * C, np.int64)
    for i in range(k * C):
        z, pos = read_varint(payload, pos)
        vals[i] = (z >> 1) ^ -(z & 1)
    if pos != len(payload):
        raise FormatError("trailing bytes in column payload")
    if np.abs(vals).max(initial=0) > Q:
        raise FormatError("quantized value out of range")
    return codes, positions, vals.reshape(k, C)


# ----------------------------------------------------------------------------
# Encodings 3 and 4: the range decoder (binary and 17-symbol contexts)


class RangeDecoder:
    """FORMAT.md "The binary coder" (encoding 3) and the symbol contexts of
    "Encoding 4". Binary contexts are two parallel lists p, n; a symbol context
    is a list of the 18 cumulative frequencies b[0..=17] plus a count in a
    parallel list."""

    def __init__(self, stream):
        self.s = stream
        self.pos = 0
        self.virtual = 0  # bytes read past the end (zeros), at most 4
        self.range = 0xFFFFFFFF
        self.code = 0
        for _ in range(4):
            self.code = (self.code << 8) | self._byte()

    def _byte(self):
        if self.pos < len(self.s):
            b = self.s[self.pos]
            self.pos += 1
            return b
        self.virtual += 1
        if self.virtual > 4:
            raise FormatError("range decoder read past the end of the stream")
        return 0

    def _renormalize(self):
        while self.range < (1 << 24):
            self.range = (self.range << 8) & 0xFFFFFFFF
            self.code = ((self.code << 8) | self._byte()) & 0xFFFFFFFF

    def bit(self, P, N, c):
        p = P[c]
        bound = (self.range >> 15) * p
        n = N[c]
        shift = min((n + 1).bit_length(), 5)  # min(1 + floor(log2(n + 1)), 5)
        if self.code < bound:
            self.range = bound
            p += (32768 - p) >> shift
            bit = 0
        else:
            self.code -= bound
            self.range -= bound
            p -= p >> shift
            bit = 1
        P[c] = 31 if p < 31 else (32737 if p > 32737 else p)
        if n < 32:
            N[c] = n + 1
        self._renormalize()
        return bit

    def symbol(self, CUM, N, c):
        """One of 17 symbols with context c (FORMAT.md "Encoding 4", steps 1-4)."""
        b = CUM[c]
        r = self.range >> 15
        s = 0
        while s < 16 and r * b[s + 1] <= self.code:  # b is increasing
            s += 1
        lo = r * b[s]
        hi = r * b[s + 1] if s < 16 else self.range
        self.code -= lo
        self.range = hi - lo
        n = N[c]
        shift = min((n + 1).bit_length(), 5)
        for i in range(1, 17):
            t = i if i <= s else 32751 + i
            b[i] += (t - b[i]) >> shift  # arithmetic shift = floor division
        if n < 32:
            N[c] = n + 1
        self._renormalize()
        return s


def new_symbol_context():
    return [1927 * s for s in range(17)] + [32768]


class RawBitReader:
    """FORMAT.md "Encoding 4": the raw bit stream, most significant bit first."""

    def __init__(self, data):
        self.data = data
        self.nbits = 0

    def bit(self):
        byte = self.nbits >> 3
        if byte >= len(self.data):
            raise FormatError("raw bit stream exhausted")
        b = (self.data[byte] >> (7 - (self.nbits & 7))) & 1
        self.nbits += 1
        return b

    def finish(self):
        if (self.nbits + 7) >> 3 != len(self.data):
            raise FormatError(f"raw bit stream: {len(self.data) - ((self.nbits + 7) >> 3)} "
                              "bytes unread")
        if self.nbits & 7 and self.data[-1] & ((1 << (8 - (self.nbits & 7))) - 1):
            raise FormatError("raw bit stream: a padding bit is set")


# Binary context tables shared by encodings 3 and 4 (the walk), one flat list.
CTX_BLOCK = 0                   # 48
CTX_SIG = CTX_BLOCK + 48        # 144
CTX_WALK = CTX_SIG + 144
# Encoding 3 value contexts follow the walk's.
CTX_ZERO = CTX_WALK             # 7
CTX_SIGN = CTX_ZERO + 7         # 7
CTX_PREFIX = CTX_SIGN + 7       # 64 x 16
CTX_SUFFIX = CTX_PREFIX + 64 * 16  # 16 x 16
CTX_TOTAL = CTX_SUFFIX + 16 * 16
# Encoding 4 binary value contexts follow the walk's; `class` (80) is a symbol table.
CTX4_SIGN = CTX_WALK            # 7
CTX4_TOP = CTX4_SIGN + 7        # 17 (top[2..=16] used)
CTX4_SECOND = CTX4_TOP + 17     # 17 x 2 (second[3..=16][0..=1] used)
CTX4_TOTAL = CTX4_SECOND + 17 * 2
CLASS4_COUNT = 80


def decode_value(dec, P, N, zc, sc, pc, nmax):
    """value(zc, sc, pc, N): zero flag, sign, unary prefix, suffix bits."""
    if not dec.bit(P, N, CTX_ZERO + zc):
        return 0
    neg = dec.bit(P, N, CTX_SIGN + sc)
    n = 0
    while n < nmax:
        if not dec.bit(P, N, CTX_PREFIX + pc * 16 + min(n, 15)):
            break
        n += 1
    m = 1
    for j in range(n - 1, -1, -1):
        m = 2 * m + dec.bit(P, N, CTX_SUFFIX + n * 16 + j)
    return -m if neg else m


def bitlen(v):
    return abs(v).bit_length()


class Values3:
    """Values of a kept pixel, FORMAT.md "Encoding 3" (prediction divides each time)."""

    def __init__(self, dec, P, N, C, B, d):
        self.dec, self.P, self.N, self.C, self.B = dec, P, N, C, B
        self.Q = (1 << (B - 1)) - 1
        self.Sxx = [0] * (d + 1)
        self.Sxy = [[0] * C for _ in range(d + 1)]

    def pixel(self, grp, cls, t):
        dec, P, N, C, B, Q = self.dec, self.P, self.N, self.C, self.B, self.Q
        Sxx, Sxy = self.Sxx, self.Sxy
        q0 = decode_value(dec, P, N, 0, 0, cls * 4 + t, B - 2)
        q = [q0]
        r1 = 0
        for c in range(1, C):
            if Sxx[grp] == 0:
                pi = 0
            else:
                pi = (2 * Sxy[grp][c] * q0 + Sxx[grp]) // (2 * Sxx[grp])
                pi = max(-Q, min(Q, pi))
            sigma = 0 if pi == 0 else (1 if pi > 0 else 2)
            if c == 1:
                z = 1 + (pi == 0)
            else:
                z = 3 + 2 * (pi == 0) + (r1 == 0)
            r = decode_value(dec, P, N, z, 1 + 3 * (c - 1) + sigma,
                             32 + 16 * (c - 1) + min(bitlen(pi), 15), B - 1)
            if c == 1:
                r1 = r
            qc = pi + r
            if abs(qc) > Q:
                raise FormatError("decoded value out of range")
            q.append(qc)
        if abs(q0) > Q:
            raise FormatError("decoded value out of range")
        for c in range(1, C):
            Sxy[grp][c] += q[c] * q0
        Sxx[grp] += q0 * q0
        return q

    def finish(self):
        pass


class Values4:
    """Values of a kept pixel, FORMAT.md "Encoding 4": 17-symbol magnitude classes,
    two context-coded bits below the leading one, raw low bits, and the group's fixed-point slope."""

    def __init__(self, dec, raw, P, N, C, B, d):
        self.dec, self.raw, self.P, self.N, self.C, self.B = dec, raw, P, N, C, B
        self.Q = (1 << (B - 1)) - 1
        self.CUM = [new_symbol_context() for _ in range(CLASS4_COUNT)]
        self.NS = [0] * CLASS4_COUNT
        self.Sxx = [0] * (d + 1)
        self.Sxy = [[0] * C for _ in range(d + 1)]
        self.rho = [[0] * C for _ in range(d + 1)]

    def value4(self, h, sc, L):
        k = self.dec.symbol(self.CUM, self.NS, h)
        if k == 0:
            return 0
        if k > L:
            raise FormatError(f"magnitude class {k} above {L}")
        neg = self.dec.bit(self.P, self.N, CTX4_SIGN + sc)
        if k == 1:
            m = 1
        else:
            u = self.dec.bit(self.P, self.N, CTX4_TOP + k)
            m = 2 + u
            if k >= 3:
                m = 2 * m + self.dec.bit(self.P, self.N, CTX4_SECOND + 2 * k + u)
                for _ in range(k - 3):
                    m = 2 * m + self.raw.bit()
        return -m if neg else m

    def pixel(self, grp, cls, t):
        C, B, Q = self.C, self.B, self.Q
        q0 = self.value4(cls * 4 + t, 0, B - 1)
        if abs(q0) > Q:
            raise FormatError("decoded value out of range")
        q = [q0]
        r1 = 0
        for c in range(1, C):
            pi = (q0 * self.rho[grp][c] + (1 << 15)) >> 16  # floor division by 2^16
            pi = max(-Q, min(Q, pi))
            sigma = 0 if pi == 0 else (1 if pi > 0 else 2)
            ell = min(bitlen(pi), 15)
            if c == 1:
                h = 32 + ell
            else:
                h = 64 + ell if r1 == 0 else 48 + ell
            r = self.value4(h, 1 + 3 * (c - 1) + sigma, B)
            if c == 1:
                r1 = r
            qc = pi + r
            if abs(qc) > Q:
                raise FormatError("decoded value out of range")
            q.append(qc)
        Sxx, Sxy = self.Sxx, self.Sxy
        for c in range(1, C):
            Sxy[grp][c] += q[c] * q0
        Sxx[grp] += q0 * q0
        for c in range(1, C):
            if Sxx[grp] == 0:
                rho = 0
            else:
                rho = ((1 << 17) * Sxy[grp][c] + Sxx[grp]) // (2 * Sxx[grp])
                rho = max(-(1 << 20), min(1 << 20, rho))
            self.rho[grp][c] = rho
        return q

    def finish(self):
        self.raw.finish()


def walk_column(dec, P, N, W, H, d, C, k, values):
    """Bands, scan order, parents, block flags and significance bits (FORMAT.md
    "Encoding 3", shared by encoding 4); `values.pixel(group, class, t)` decodes
    the values of each kept pixel. Returns (positions, values (k, C))."""
    mag = [0] * (W * H)
    positions, out = [], []
    left = k
    blist = bands(W, H, d)
    # parent of each band: index into blist and shift
    parent = [None]
    for bi in range(1, len(blist)):
        grp, orient = blist[bi][4], blist[bi][5]
        if grp == d:
            parent.append((0, 0))
        else:
            # same orientation at level grp + 1: appears 3 entries earlier
            parent.append((bi - 3, 1))
    for bi, (x0, x1, y0, y1, grp, orient) in enumerate(blist):
        if left == 0:
            break
        bw, bh = x1 - x0, y1 - y0
        if bw <= 0 or bh <= 0:
            continue
        cls = 0 if bi == 0 else min(grp, 7)
        par = parent[bi]
        if par is not None:
            px0, px1, py0, py1 = blist[par[0]][:4]
            pw, ph, shift = px1 - px0, py1 - py0, par[1]
            if pw <= 0 or ph <= 0:
                par = None

        def pmag(u, v):
            if par is None:
                return 0
            return mag[(py0 + min(v >> shift, ph - 1)) * W + px0 + min(u >> shift, pw - 1)]

        def nb(u, v):  # neighbour magnitude within the band, 0 outside
            if 0 <= u < bw and 0 <= v < bh:
                return mag[(y0 + v) * W + x0 + u]
            return 0

        nbx, nby = (bw + 3) // 4, (bh + 3) // 4
        flags = [[0] * nbx for _ in range(nby)]
        for by in range(nby):
            if left == 0:
                break
            for bx in range(nbx):
                if left == 0:
                    break
                a = (flags[by][bx - 1] if bx > 0 else 0) + (flags[by - 1][bx] if by > 0 else 0)
                u0, v0 = 4 * bx, 4 * by
                u1, v1 = min(u0 + 3, bw - 1), min(v0 + 3, bh - 1)
                b = 1 if (pmag(u0, v0) or pmag(u1, v0) or pmag(u0, v1) or pmag(u1, v1)) else 0
                f = dec.bit(P, N, CTX_BLOCK + (cls * 3 + a) * 2 + b)
                flags[by][bx] = f
                if not f:
                    continue
                any_kept = False
                for v in range(v0, v1 + 1):
                    if left == 0:
                        break
                    for u in range(u0, u1 + 1):
                        if u == u1 and v == v1 and not any_kept:
                            kept = 1
                        else:
                            a2 = (nb(u - 1, v) > 0) + (nb(u, v - 1) > 0)
                            e2 = (nb(u - 1, v - 1) > 0) + (nb(u + 1, v - 1) > 0)
                            b2 = 1 if pmag(u, v) else 0
                            kept = dec.bit(P, N, CTX_SIG + ((cls * 3 + a2) * 3 + e2) * 2 + b2)
                        if not kept:
                            continue
                        any_kept = True
                        # values of a kept pixel; t buckets the left + upper mag classes
                        s = nb(u - 1, v) + nb(u, v - 1)
                        t = 0 if s == 0 else (1 if s <= 3 else (2 if s <= 7 else 3))
                        q = values.pixel(grp, cls, t)
                        i = (y0 + v) * W + x0 + u
                        L = max(bitlen(x) for x in q)
                        mag[i] = min(max(1, L), 15)
                        positions.append(i)
                        out.append(q)
                        left -= 1
                        if left == 0:
                            break
    if left != 0:
        raise FormatError("range-coded column ended before all positions were found")
    if dec.pos != len(dec.s):
        raise FormatError(f"range-coded column: {len(dec.s) - dec.pos} stream bytes unread")
    values.finish()
    order = np.argsort(positions, kind="stable")
    return (np.asarray(positions, np.int64)[order],
            np.asarray(out, np.int64).reshape(k, C)[order])


def decode_range_stream(stream, W, H, d, C, B, k):
    """FORMAT.md "Encoding 3": the walk with encoding 3's values."""
    dec = RangeDecoder(stream)
    P = [16384] * CTX_TOTAL
    N = [0] * CTX_TOTAL
    return walk_column(dec, P, N, W, H, d, C, k, Values3(dec, P, N, C, B, d))


def decode_range_stream4(stream, raw, W, H, d, C, B, k):
    """FORMAT.md "Encoding 4": the same walk, values as classes + raw low bits."""
    dec = RangeDecoder(stream)
    P = [16384] * CTX4_TOTAL
    N = [0] * CTX4_TOTAL
    values = Values4(dec, RawBitReader(raw), P, N, C, B, d)
    return walk_column(dec, P, N, W, H, d, C, k, values)


def decode_payload_range(payload, W, H, d, C, B, k):
    ns = (d + 1) * C
    if len(payload) < 2 * ns:
        raise FormatError("range-coded payload shorter than its scale codes")
    codes = np.frombuffer(payload, "<u2", ns, 0).reshape(d + 1, C)
    positions, values = decode_range_stream(payload[2 * ns:], W, H, d, C, B, k)
    return codes, positions, values


def decode_payload_range4(payload, W, H, d, C, B, k):
    """Encoding 4: scale codes, u32 R, R bytes of range-coded stream, raw bits."""
    ns = (d + 1) * C
    if len(payload) < 2 * ns + 4:
        raise FormatError("encoding-4 payload shorter than its scale codes and length")
    codes = np.frombuffer(payload, "<u2", ns, 0).reshape(d + 1, C)
    R, = struct.unpack_from("<I", payload, 2 * ns)
    start = 2 * ns + 4
    if R > len(payload) - start:
        raise FormatError("encoding-4 range-coded stream longer than the payload")
    stream, raw = payload[start:start + R], payload[start + R:]
    positions, values = decode_range_stream4(stream, raw, W, H, d, C, B, k)
    return codes, positions, values


def decode_payload_range5(payload, W, H, d, C, B, k, priors=None):
    """Encoding 5: varint R, R bytes of range-coded stream, raw bits; the scale codes
    come first in the streams (contexts `same` and `zero`), then encoding 4's walk.
    Encoding 6 is the same with every context starting in `priors` (parse_priors)."""
    R, at = 0, 0
    while True:
        if at >= len(payload):
            raise FormatError("encoding-5 length varint runs past the payload")
        b = payload[at]
        R |= (b & 0x7F) << (7 * at)
        at += 1
        if not b & 0x80:
            if at > 1 and b == 0:
                raise FormatError("encoding-5 length varint ends in a zero byte")
            break
        if at == 5:
            raise FormatError("encoding-5 length varint longer than 5 bytes")
    if R > len(payload) - at:
        raise FormatError("encoding-5 range-coded stream longer than the payload")
    dec = RangeDecoder(payload[at:at + R])
    raw = RawBitReader(payload[at + R:])
    SP, SN = [16384, 16384], [0, 0]  # contexts `same` (0) and `zero` (1)
    if priors is not None:
        SP, SN = list(priors["SP"]), list(priors["SN"])
    codes, last = [], None  # last: the last nonzero code
    for i in range((d + 1) * C):
        if last is not None and dec.bit(SP, SN, 0):
            e = last
        elif dec.bit(SP, SN, 1):
            e = 0
        else:
            e = 0
            for _ in range(16):
                e = (e << 1) | raw.bit()
        codes.append(e)
        if e:
            last = e
    codes = np.asarray(codes, np.uint16).reshape(d + 1, C)
    P = [16384] * CTX4_TOTAL
    N = [0] * CTX4_TOTAL
    values = Values4(dec, raw, P, N, C, B, d)
    if priors is not None:
        P[:], N[:] = priors["P"], priors["N"]
        values.CUM = [list(c) for c in priors["CUM"]]
        values.NS = list(priors["NS"])
    positions, vals = walk_column(dec, P, N, W, H, d, C, k, values)
    return codes, positions, vals


# ----------------------------------------------------------------------------
# Inverse transforms


def inverse_1d_periodic(x, n, lo, along_x):
    """Inverse 1D step along axis 0 of x[:n], in place, in x's precision.

    FORMAT.md "Inverse transforms": along y each x[k] adds its terms in tap order
    j = 0..F-1; along x the terms are added for o = 0..m/2-1, within each o for
    j = 0..F-1 (the two orders differ in f32 where the period wraps around)."""
    F = len(lo)
    hi = [(-1) ** (j + 1) * lo[F - 1 - j] for j in range(F)]
    lo = [x.dtype.type(t) for t in lo]
    hi = [x.dtype.type(t) for t in hi]
    nl = (n + 1) // 2
    low = x[:nl].copy()
    high = x[nl:n].copy()
    m = n - (n & 1)
    h = m // 2
    out = np.zeros_like(x[:n])
    if along_x:
        for o in range(h):
            for j in range(F):
                out[(2 * o + F // 2 - j) % m] += lo[j] * low[o] + hi[j] * high[o]
    else:
        o = np.arange(h)
        for j in range(F):
            idx = (2 * o + F // 2 - j) % m  # distinct for distinct o
            out[idx] += lo[j] * low[:h] + hi[j] * high[:h]
    if n & 1:
        out[n - 1] = low[(n - 1) // 2]
    x[:n] = out


def inverse_1d_lifting(x, n, filt, along_x):
    steps, low_scale, high_scale = LIFTING[filt]
    t = x.dtype.type  # constants rounded to the working precision (f32 in ltm)
    nl = (n + 1) // 2
    y = np.empty_like(x[:n])
    if along_x:  # the row pass divides by the scales
        y[0::2] = x[:nl] / t(low_scale)
        y[1::2] = x[nl:n] / t(high_scale)
    else:  # the column pass multiplies by their reciprocals rounded to f32
        y[0::2] = x[:nl] * t(1.0 / t(low_scale))
        y[1::2] = x[nl:n] * t(1.0 / t(high_scale))
    e = (n - 1) if (n - 1) % 2 == 0 else n - 2  # last even index
    o = (n - 1) if (n - 1) % 2 == 1 else n - 2  # last odd index
    for kind, c in reversed(steps):
        c = t(c)
        if kind == "predict":
            k = np.arange(1, n, 2)
            y[k] -= c * (y[k - 1] + y[np.minimum(k + 1, e)])
        else:
            k = np.arange(0, n, 2)
            left = np.where(k - 1 < 0, 1, k - 1)
            y[k] -= c * (y[left] + y[np.minimum(k + 1, o)])
    x[:n] = y


def inverse_1d(x, n, filt, along_x):
    if filt in LIFTING:
        inverse_1d_lifting(x, n, filt, along_x)
    else:
        inverse_1d_periodic(x, n, DEC_LO[filt], along_x)


def inverse_2d(img, levels, filt):
    """Inverse of `levels` 2D steps; img has shape (H, W, ...) and is modified in place."""
    H, W = img.shape[0], img.shape[1]
    for k in range(levels - 1, -1, -1):
        w, h = band_size(W, H, k)
        if h >= 2:  # every column of the region
            inverse_1d(img[:h, :w], h, filt, False)
        if w >= 2:  # every row of the region
            region = np.swapaxes(img[:h, :w], 0, 1)  # a view: (w, h, ...)
            inverse_1d(region, w, filt, True)
    return img


# ----------------------------------------------------------------------------
# Dequantization and band weights

_weight_cache = {}


def band_weights(W, H, d, filt, dt):
    """w_d per position (H*W,), FORMAT.md "Band weights", for every filter.

    In f32 the sum of squares is accumulated sequentially in raster order, which
    reproduces ltm's weights bit for bit on the test files."""
    key = (W, H, d, filt, dt)
    if key in _weight_cache:
        return _weight_cache[key]
    w = np.ones((H, W), dt)
    if d > 0:  # every filter: ~1 for the orthonormal ones, and ltm uses that value
        for x0, x1, y0, y1, _g, _orient in bands(W, H, d):
            if x0 >= x1 or y0 >= y1:
                continue
            cx, cy = (x0 + x1) // 2, (y0 + y1) // 2
            imp = np.zeros((H, W), dt)
            imp[cy, cx] = 1
            inverse_2d(imp, d, filt)
            sumsq = np.cumsum((imp * imp).ravel(), dtype=dt)[-1]
            w[y0:y1, x0:x1] = max(dt(1e-6), np.sqrt(sumsq))
    w = w.reshape(-1)
    _weight_cache[key] = w
    return w


def scales_from_codes(codes, dt):
    e = codes.astype(np.float64)
    s = np.exp2((e - 32768.0) / 256.0)
    s[codes == 0] = 0.0
    return s.astype(dt)


def dequantize_column(codes, positions, values, W, H, d, C, B, filt, dt):
    """Column image coefficients v (H*W, C), before the inverse column transform.

    v = u * (1/w), the reciprocal rounded to the working precision, as FORMAT.md
    "Decoding a column" step 2 says (in f32 only this matches bit for bit)."""
    Q = (1 << (B - 1)) - 1
    s = scales_from_codes(codes, dt)                  # (d+1, C)
    g = group_map(W, H, d)[positions]                 # (k,)
    u = np.zeros((W * H, C), dt)
    u[positions] = values.astype(dt) * s[g] / dt(Q)
    return u * (dt(1) / band_weights(W, H, d, filt, dt))[:, None]


# ----------------------------------------------------------------------------
# The pipeline


def decode_matrix(path, verbose=False, dt=np.float32, info=None):
    """Decode the file to T; `info` (a dict), if given, receives the format version,
    the META fields and the number of columns of each encoding."""
    buf = open(path, "rb").read()
    chunks, version, features = read_container(buf)
    meta = parse_meta(chunks[b"META"])
    W, H, n, C, B = meta["W"], meta["H"], meta["n"], meta["C"], meta["bits"]
    P, M = W * H, 6 * n * n
    Q = (1 << (B - 1)) - 1
    empty = parse_empty_rows(chunks[b"EMPT"], P) if b"EMPT" in chunks else None
    norms = parse_norms(chunks[b"NORM"], M) if b"NORM" in chunks else None
    priors = parse_priors(chunks[b"PRIO"]) if b"PRIO" in chunks else None
    layout = parse_surf(chunks[b"SURF"], W, H)[0] if b"SURF" in chunks else 0
    mesh = None
    if b"MESH" in chunks:
        if layout != 1:
            raise FormatError("a MESH chunk in an image-space file")
        mesh = parse_mesh(chunks[b"MESH"], W)
    near = parse_near(chunks[b"NEAR"], P, C) if b"NEAR" in chunks else None
    table = parse_column_table(chunks[b"COLS"], M, P, W, H, version)
    data = chunks[b"DATA"]
    if info is not None:
        info.update(meta, version=version, features=features, mesh=mesh, near=near,
                    encodings={e: sum(1 for t in table if t["enc"] == e)
                               for e in sorted({t["enc"] for t in table})})
    if verbose:
        print(f"version {version}, features {features}, W={W} H={H} n={n} C={C} B={B} "
              f"mode={meta['mode']} rows={FILTER_NAMES[meta['row_filter']]} "
              f"columns={FILTER_NAMES[meta['col_filter']]}", file=sys.stderr)

    # Coefficients of T.R^T, grouped by column depth: by_depth[d] = list of (j, v (P, C))
    by_depth = {}
    for j, ent in enumerate(table):
        d, k, enc = ent["d"], ent["k"], ent["enc"]
        if enc == 0:
            if k != 0 or ent["slen"] != 0:
                raise FormatError(f"column {j}: empty column with a payload")
            if norms is not None and norms[j] != 0:
                raise FormatError(f"column {j}: empty column with norm {norms[j]}")
            continue
        stored = data[ent["off"]:ent["off"] + ent["slen"]]
        if len(stored) != ent["slen"] or crc32(stored) != ent["crc"]:
            raise FormatError(f"column {j}: payload outside DATA or CRC mismatch")
        if enc == 2:
            import zstandard
            payload = zstandard.ZstdDecompressor().decompress(stored, max_output_size=ent["ulen"])
        else:
            payload = stored
        if len(payload) != ent["ulen"]:
            raise FormatError(f"column {j}: decompressed length mismatch")
        if enc == 3:
            if k < 1 or ent["slen"] != ent["ulen"]:
                raise FormatError(f"column {j}: bad encoding-3 entry")
            codes, positions, values = decode_payload_range(payload, W, H, d, C, B, k)
        elif enc == 4:
            if k < 1 or ent["slen"] != ent["ulen"]:
                raise FormatError(f"column {j}: bad encoding-4 entry")
            codes, positions, values = decode_payload_range4(payload, W, H, d, C, B, k)
        elif enc in (5, 6):
            if k < 1 or ent["slen"] != ent["ulen"] or ent["slen"] < 3:
                raise FormatError(f"column {j}: bad encoding-{enc} entry")
            if enc == 6 and priors is None:
                raise FormatError(f"column {j}: encoding 6 in a file without PRIO")
            codes, positions, values = decode_payload_range5(
                payload, W, H, d, C, B, k, priors if enc == 6 else None)
        else:
            codes, positions, values = decode_payload_plain(payload, d, C, k, Q)
        if len(positions) and (positions[-1] >= P or positions[0] < 0):
            raise FormatError(f"column {j}: position out of range")
        if norms is not None:
            got = column_norm(codes, positions, values, W, H, d, C, B, dt)
            # Bit for bit in f32; f64 differs by rounding only.
            ok = got == norms[j] if dt == np.float32 else abs(got - norms[j]) <= 1e-6 * norms[j]
            if not ok:
                raise FormatError(f"column {j}: norm {got} decoded, {norms[j]} stored")
        v = dequantize_column(codes, positions, values, W, H, d, C, B, meta["col_filter"], dt)
        by_depth.setdefault(d, []).append((j, v))

    A = np.zeros((P, M, C), dt)  # T.R^T
    for d, cols in by_depth.items():
        js = [j for j, _ in cols]
        stack = np.stack([v for _, v in cols], axis=1)        # (P, ncols, C)
        img = stack.reshape(H, W, len(js) * C)
        inverse_2d(img, d, meta["col_filter"])
        A[:, js, :] = img.reshape(P, len(js), C)
    if empty is not None:
        A[empty] = 0.0

    # Inverse row transform over every cube face (log2(n) levels, row filter).
    levels = n.bit_length() - 1
    faces = A.reshape(P, 6, n, n, C).transpose(2, 3, 0, 1, 4).copy()  # (row, col, P, 6, C)
    inverse_2d(faces, levels, meta["row_filter"])
    T = faces.transpose(2, 3, 0, 1, 4).reshape(P, M, C)
    if empty is not None:
        T[empty] = 0.0
    T = T.astype(np.float32)
    return T[:, :, 0] if C == 1 else T


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("file")
    ap.add_argument("--compare", help="an `ltm export` .npy of the same file")
    ap.add_argument("--out", help="write the decoded matrix as .npy")
    ap.add_argument("--f64", action="store_true",
                    help="compute in float64 (default: float32, as ltm does)")
    ap.add_argument("--mesh-json", help="write the receiving mesh (or null) as JSON")
    ap.add_argument("--near-json", help="write the near-field rows (or null) as JSON")
    ap.add_argument("-v", "--verbose", action="store_true")
    args = ap.parse_args(argv)
    info = {}
    with open(args.file, "rb") as f:
        raw = f.read(8) == RAW_MAGIC
    if raw:
        try:
            info = read_raw_store(open(args.file, "rb").read())
        except FormatError as e:
            print(f"{args.file}: {e}", file=sys.stderr)
            return 2
        mesh = info["mesh"]
        part = (f", part: rows {info['rows'][0]}..{info['rows'][1]}"
                if info["version"] == 5 else "")
        print(f"raw store version {info['version']}, W={info['W']} H={info['H']} "
              f"n={info['n']} C={info['C']}{part}, mesh: "
              + (f"{len(mesh['positions'])} vertices, {len(mesh['triangles'])} triangles"
                 if mesh else "none"))
        if args.mesh_json:
            import json
            json.dump(mesh_json(mesh), open(args.mesh_json, "w"))
        return 0
    try:
        T = decode_matrix(args.file, args.verbose, np.float64 if args.f64 else np.float32, info)
    except FormatError as e:
        print(f"{args.file}: {e}", file=sys.stderr)
        return 2
    print("shape", T.shape)
    print(f"format version {info['version']}, columns by encoding "
          + ", ".join(f"{e}: {c}" for e, c in info["encodings"].items()))
    mesh = info["mesh"]
    if mesh is not None:
        print(f"receiver mesh: {len(mesh['positions'])} vertices, "
              f"{len(mesh['triangles'])} triangles")
    if args.mesh_json:
        import json
        json.dump(mesh_json(mesh), open(args.mesh_json, "w"))
    near = info["near"]
    if near is not None:
        plane, rows = near
        print(f"near-field rows: order {plane['order']}, side {plane['side']}, "
              f"{sum(len(k) for k, _ in rows)} coefficients")
    if args.near_json:
        import json
        json.dump(near_json(near), open(args.near_json, "w"))
    if args.out:
        np.save(args.out, T)
    if args.compare:
        ref = np.load(args.compare)
        if ref.shape != T.shape:
            print(f"shape mismatch: export has {ref.shape}")
            return 1
        diff = T.astype(np.float64) - ref.astype(np.float64)
        mx = float(np.abs(diff).max()) if diff.size else 0.0
        nr = float(np.linalg.norm(ref.astype(np.float64)))
        rel = float(np.linalg.norm(diff)) / nr if nr > 0 else float(np.linalg.norm(diff))
        print(f"max abs diff {mx:.6g}  relative L2 diff {rel:.6g}  "
              f"(bit-exact entries {np.mean(diff == 0) * 100:.2f}%)")
        if not rel <= 1e-5:
            return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
