#!/usr/bin/env python3
"""Regenerate the committed seed corpora (fuzz/seeds/<target>/) from the
project's own data: data/example, host-tools/tests/fixtures, the images in
fuzz/images/ (written by `dynocomp design` on the bundled example) and a few
hand-made inputs. Run from the repository root: python3 fuzz/make_seeds.py

Seeds stay small (a few KiB each): big inputs slow every execution.
Public vendor files (e.g. the pyuff samples) are NOT committed; see
docs/fuzzing.md for seeding the long campaigns with them locally.
"""
import os
import struct
import zlib

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SEEDS = os.path.join(ROOT, "fuzz", "seeds")


def put(target, name, data):
    d = os.path.join(SEEDS, target)
    os.makedirs(d, exist_ok=True)
    with open(os.path.join(d, name), "wb") as f:
        f.write(data if isinstance(data, bytes) else data.encode())


def head_lines(path, n):
    with open(os.path.join(ROOT, path), "rb") as f:
        return b"".join(f.readlines()[:n])


def read(path):
    with open(os.path.join(ROOT, path), "rb") as f:
        return f.read()


# FRF CSV: heads of the example and of the fixtures' expected CSVs, hand-made.
put("frf_csv", "example_head.csv", head_lines("data/example/frf.csv", 24))
fx = "host-tools/tests/fixtures/uff"
for name in sorted(os.listdir(os.path.join(ROOT, fx))):
    if name.endswith(".expected.csv"):
        put("frf_csv", name, head_lines(f"{fx}/{name}", 16))
put("frf_csv", "coherence.csv", "freq_hz,x_re,x_im,x_coh,z_re,z_im,z_coh\n0,1,0,1,1,0,0.5\n10.5,0.9,-0.1,0.99,1.1,0.2,1\n")
put("frf_csv", "crlf_quoted.csv", '"freq_hz","y_re","y_im"\r\n1e1,1.0,-2.5e-3\r\n2e1,1.01,-3e-3\r\n')

# UFF 58 / 58b: the project's fixtures (ASCII single/double, uneven, binary),
# whole when they fit the campaign's -max_len (fuzz/campaign.sh, 8 KiB), and
# each dataset on its own, so that every seed is a complete, readable file
# within that length.
UFF_MAX_LEN = 8192


def uff_datasets(data):
    """The `    -1` ... `    -1` blocks of a UFF file (ASCII framing; a
    binary 58b block is kept whole when its bytes do not contain the
    delimiter line)."""
    delim = b"    -1\n"
    parts = data.split(delim)
    # parts: '', body1, '\n'?, body2, ... : the bodies are the odd ones.
    return [delim + body + delim for body in parts[1::2] if body.strip()]


for name in sorted(os.listdir(os.path.join(ROOT, fx))):
    if name.endswith(".uff"):
        data = read(f"{fx}/{name}")
        if len(data) <= UFF_MAX_LEN:
            put("uff58", name, data)
        for k, ds in enumerate(uff_datasets(data)):
            if len(ds) <= UFF_MAX_LEN and ds != data:
                put("uff58", f"{name}.ds{k}", ds)

# Signal CSV: heads of the example records, hand-made variants.
put("signal_csv", "measured_head.csv", head_lines("data/example/measured.csv", 24))
put("signal_csv", "idle_head.csv", head_lines("data/example/idle.csv", 24))
put("signal_csv", "raw_columns.csv", "t_s,fx,fz,raw_fx,raw_fz\n0,1.5,2,3,4\n1.953125e-5,-1,0,0,0\n")
put("signal_csv", "no_time.csv", "fy\n1\n2\n3\n")

# TDMS: the npTDMS-written fixture, and small hand-built files after NI's
# layout: interleaved f64 in two segments (the second without metadata),
# contiguous big-endian i16/f32 with two chunks, and a file with incremental
# metadata (index "same as before", a kN unit added later).
def tdms_segment(toc, objs, raw, big=False):
    e = ">" if big else "<"
    m = b""
    if objs is not None:
        m += struct.pack(e + "I", len(objs))
        for path, index, props in objs:
            m += struct.pack(e + "I", len(path)) + path.encode()
            if index is None:
                m += struct.pack(e + "I", 0xFFFFFFFF)
            elif index == "same":
                m += struct.pack(e + "I", 0)
            else:
                ty, n = index
                m += struct.pack(e + "IIIQ", 20, ty, 1, n)
            m += struct.pack(e + "I", len(props))
            for k, v in props:
                m += struct.pack(e + "I", len(k)) + k.encode()
                if isinstance(v, str):
                    m += struct.pack(e + "II", 0x20, len(v)) + v.encode()
                else:
                    m += struct.pack(e + "Id", 10, v)
    lead = b"TDSm" + struct.pack("<I", toc) + struct.pack(e + "IQQ", 4713, len(m) + len(raw), len(m))
    return lead + m + raw


put("tdms", "nptdms_two_segments.tdms", read("host-tools/tests/fixtures/tdms/nptdms_two_segments.tdms"))
wf = [("wf_increment", 1 / 51200), ("unit_string", "N")]
chans = [("/'g'/'Fx'", (10, 4), wf), ("/'g'/'Fy'", (10, 4), wf), ("/'g'/'Fz'", (10, 4), wf)]
raw = b"".join(struct.pack("<d", k * 0.5 - 1) for k in range(12))
put("tdms", "interleaved.tdms", tdms_segment(0x2E, [("/", None, [("name", "seed")]), ("/'g'", None, [])] + chans, raw) + tdms_segment(0x28, None, raw))
be = [("/'Dyno'/'Force X'", (2, 3), [("wf_increment", 1 / 25600)]), ("/'Dyno'/'Force Z'", (9, 3), [])]
raw = struct.pack(">hhh", -1, 2, 300) + struct.pack(">fff", 0.5, -1.5, 2.5)
put("tdms", "contiguous_be.tdms", tdms_segment(0x4E, be, raw + raw, big=True))
one = [("/'c'/'force_y'", (10, 2), [])]
put("tdms", "incremental.tdms", tdms_segment(0x0E, one, struct.pack("<dd", 1, 2)) + tdms_segment(0x0A, [("/'c'/'force_y'", "same", [("unit_string", "kN")])], struct.pack("<dd", 3, 4)))

# Image codec: mode byte (bit 0: repair CRC, bit 1: format 2 first, bit 2:
# format 3 first) + image. matrix*.dcimg are 3x3 images (format 3): the
# realistic filter of tests/image_matrix.rs and the worked example of
# docs/image-format.md section 13.7.
for name in sorted(os.listdir(os.path.join(ROOT, "fuzz", "images"))):
    if not name.endswith(".dcimg"):
        continue
    img = read(f"fuzz/images/{name}")
    for mode in (0, 1, 4, 5) if name.startswith("matrix") else (0, 1, 2, 3):
        put("image", f"{name}.mode{mode}", bytes([mode]) + img)

# Protocol: mode 1 (payload, framed by the target) and mode 0 (raw wire).
def varint(v):
    out = bytearray()
    while True:
        b = v & 0x7F
        v >>= 7
        if v:
            out.append(b | 0x80)
        else:
            out.append(b)
            return bytes(out)


def cobs(data):
    out, block = bytearray(), bytearray()
    for b in data:
        if b == 0:
            out += bytes([len(block) + 1]) + block
            block = bytearray()
        else:
            block.append(b)
            if len(block) == 254:
                out += bytes([255]) + block
                block = bytearray()
    out += bytes([len(block) + 1]) + block
    return bytes(out)


def frame(payload):
    return cobs(payload + struct.pack("<I", zlib.crc32(payload))) + b"\x00"


example = read("fuzz/images/example.dcimg")
requests = {
    "get_status": varint(1) + b"\x00",
    "set_bypass": varint(2) + b"\x01\x01",
    "start_stream": varint(3) + b"\x02" + varint(8),
    "stop_stream": varint(4) + b"\x03",
    "upload_begin": varint(5) + b"\x04" + varint(len(example)) + varint(zlib.crc32(example)),
    "upload_chunk": varint(6) + b"\x05" + varint(0) + varint(64) + example[:64],
    "upload_commit": varint(7) + b"\x06",
    "auto_zero": varint(8) + b"\x07",
}
for name, payload in requests.items():
    put("protocol", f"{name}.payload", b"\x01" + payload)
    put("protocol", f"{name}.wire", b"\x00" + frame(payload))
put("protocol", "session.wire", b"\x00" + b"".join(frame(p) for p in requests.values()))
put("protocol", "garbage.wire", b"\x00\x01\x02\x00\xff\xff\x00")

# Model sidecar: the example image's own sidecar, and a foreign one.
put("sidecar", "example.model.json", read("fuzz/images/example.dcimg.model.json"))
put("sidecar", "foreign.model.json", read("fuzz/images/lat0.dcimg.model.json"))
# The example's sidecar with a small 3x3 model (the part a 3x3 image's
# sidecar adds; host-tools/src/offline/matrix_smoother.rs).
import json
_with_matrix = json.loads(read("fuzz/images/example.dcimg.model.json"))
_with_matrix["matrix"] = {
    "advance": 1,
    "plant_a": [[0.5, 0.0, 0.0], [0.0, 0.3, 0.1], [0.0, -0.1, 0.3]],
    "plant_b": [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
    "plant_c": [[0.2, 0.05, 0.0], [0.0, 0.3, 0.02], [0.01, 0.0, 0.4]],
    "d": [[1.0, 0.1, 0.0], [0.05, 1.0, 0.1], [0.0, 0.2, 1.0]],
    "fir": [[[0.01, 0.0, 0.0], [0.0, 0.02, 0.0], [0.0, 0.0, 0.03]]],
    "q": [100.0, 50.0, 200.0],
    "r": [0.05, 0.05, 0.1],
    "force_shape": [{"corner_hz": 4800.0, "order": 4}, None, {"corner_hz": 6000.0, "order": 2}],
}
put("sidecar", "with-matrix.model.json", json.dumps(_with_matrix, indent=1))

# UFF 58 / 58b time histories (function type 1): heads of the example's
# measured record, written in the layout of the project's writer
# (io/uff_signal.rs: ASCII double 4E20.12, 58b little-endian doubles) and in
# single precision (ASCII 6E13.5, 58b floats), a negative direction, and a
# file whose first dataset is an FRF (skipped by the reader).
def uff_time_dataset(axis_dir, values, dt, ord_type=4, binary=False, big_endian=False):
    double = ord_type == 4
    n = len(values)
    out = "%6d\n" % -1
    if binary:
        nbytes = n * (8 if double else 4)
        out += "%6db%6d%6d%12d%12d%6d%6d%12d%12d\n" % (58, 2 if big_endian else 1, 2, 11, nbytes, 0, 0, 0, 0)
    else:
        out += "%6d%74s\n" % (58, "")
    for ident in ["seed f%d" % abs(axis_dir), "NONE", "NONE", "NONE", "NONE"]:
        out += "%-80s\n" % ident
    out += "%5d%10d%5d%10d %10s%10d%4d %10s%10d%4d\n" % (1, abs(axis_dir), 0, 0, "DYN", 1, axis_dir, "HAMMER", 1, axis_dir)
    out += "%10d%10d%10d%13.6e%13.6e%13.6e\n" % (ord_type, n, 1, 0.0, dt, 0.0)
    for spec, label, units in [(17, "Time", "s"), (9, "Force", "N"), (0, "NONE", "NONE"), (0, "NONE", "NONE")]:
        out += "%10d%5d%5d%5d %-20s %-20s\n" % (spec, 0, 0, 0, label, units)
    data = out.encode()
    if binary:
        fmt = (">" if big_endian else "<") + ("d" if double else "f") * n
        data += struct.pack(fmt, *values)
    else:
        per, f = (4, "%20.12e") if double else (6, "%13.5e")
        lines = ["".join(f % v for v in values[i:i + per]) for i in range(0, n, per)]
        data += ("\n".join(lines) + "\n").encode()
    return data + ("%6d\n" % -1).encode()


rows = head_lines("data/example/measured.csv", 25).decode().splitlines()
cols = rows[0].split(",")
table = [[float(v) for v in r.split(",")] for r in rows[1:]]
chans = {c: [row[i] for row in table] for i, c in enumerate(cols) if c in ("fx", "fy", "fz")}
dt = 1.0 / 51200.0
xyz = [(1, chans["fx"]), (2, chans["fy"]), (3, chans["fz"])]
put("uff_signal", "ascii_double_xyz.uff", b"".join(uff_time_dataset(d, v, dt) for d, v in xyz))
put("uff_signal", "ascii_single_xz.uff", b"".join(uff_time_dataset(d, v, dt, ord_type=2) for d, v in xyz[::2]))
put("uff_signal", "binary_double_xyz.uff", b"".join(uff_time_dataset(d, v, dt, binary=True) for d, v in xyz))
put("uff_signal", "binary_single_be_y.uff", uff_time_dataset(2, chans["fy"], dt, ord_type=2, binary=True, big_endian=True))
put("uff_signal", "ascii_negative_z.uff", uff_time_dataset(-3, chans["fz"], dt))
frf_ds = uff_datasets(read(f"{fx}/ascii_single_xz.uff"))[0]
put("uff_signal", "frf_then_time.uff", frf_ds + uff_time_dataset(1, chans["fx"], dt))

# The FRF matrix: FRF CSV <i><j>_ columns, UFF 58 FRFs with a reference
# (hammer) direction of their own, and one matrix from several files
# (frf_merge: a mode byte whose bits 0-2 mark the UFF files, then the files
# separated by 0x1E).
def matrix_csv(entries, n=4, coh=()):
    head = ["freq_hz"]
    for e in entries:
        head += [e + "_re", e + "_im"] + ([e + "_coh"] if e in coh else [])
    rows = [",".join(head)]
    for k in range(n):
        row = ["%g" % (8.0 * k)]
        for m, e in enumerate(entries):
            row += ["%g" % (1.0 + 0.25 * k + m), "%g" % (-0.125 * k * m)] + (["%g" % (1.0 - 0.125 * k)] if e in coh else [])
        rows.append(",".join(row))
    return "\n".join(rows) + "\n"


ALL9 = [i + j for i in "xyz" for j in "xyz"]
put("frf_csv", "matrix_full.csv", matrix_csv(ALL9, coh=("xx", "xy", "zz")))
put("frf_csv", "matrix_short_names.csv", matrix_csv(["x", "xy", "xz", "y", "z"], coh=("x", "xz")))
put("frf_csv", "matrix_column_y.csv", matrix_csv(["xy", "yy", "zy"], coh=("yy",)))


def uff_frf_dataset(rsp, ref, values, coherence=False, n=4, df=8.0, units="N"):
    """An ASCII dataset 58 in the layout of io/uff.rs's writer: complex double
    FRF (4E20.12) or real double coherence."""
    ft, ord_type = (6, 4) if coherence else (4, 6)
    out = "%6d\n%6d%74s\n" % (-1, 58, "")
    for ident in ["seed %d %d" % (rsp, ref), "NONE", "NONE", "NONE", "NONE"]:
        out += "%-80s\n" % ident
    out += "%5d%10d%5d%10d %10s%10d%4d %10s%10d%4d\n" % (ft, 1, 0, 0, "DYN", 1, rsp, "HAMMER", 1, ref)
    out += "%10d%10d%10d%13.6e%13.6e%13.6e\n" % (ord_type, n, 1, 0.0, df, 0.0)
    num, den = ((0, "NONE"), (0, "NONE")) if coherence else ((9, units), (13, units))
    for spec, u in [(18, "Hz"), num, den, (0, "NONE")]:
        out += "%10d%5d%5d%5d %-20s %-20s\n" % (spec, 0, 0, 0, "NONE", u)
    lines = ["".join("%20.12e" % v for v in values[i:i + 4]) for i in range(0, len(values), 4)]
    return (out + "\n".join(lines) + "\n" + "%6d\n" % -1).encode()


def frf_vals(m, n=4):
    return [v for k in range(n) for v in (1.0 + 0.25 * k + m, -0.125 * k * m)]


def coh_vals(n=4):
    return [1.0 - 0.125 * k for k in range(n)]


def uff_column(j, sign=1):
    """Hammer direction j (1..3): the three channels' FRFs, coherence on the direct one."""
    out = b""
    for i in (1, 2, 3):
        out += uff_frf_dataset(i, sign * j, frf_vals(3 * i + j))
        if i == j:
            out += uff_frf_dataset(i, sign * j, coh_vals(), coherence=True)
    return out


put("uff58", "matrix_column_x.uff", uff_column(1))
put("uff58", "matrix_column_y_negative_ref.uff", uff_column(2, sign=-1))
put("uff58", "matrix_full.uff", uff_column(1) + uff_column(2) + uff_column(3))
put("uff58", "matrix_rotational_ref.uff", uff_frf_dataset(1, 5, frf_vals(0)) + uff_frf_dataset(1, 1, frf_vals(1)))
put("uff58", "matrix_mixed_units.uff", uff_frf_dataset(1, 1, frf_vals(0)) + uff_frf_dataset(2, 1, frf_vals(1), units="lbf"))

SEP = b"\x1e"
cols = [matrix_csv([i + j for i in "xyz"], coh=(j + j,)).encode() for j in "xyz"]
put("frf_merge", "csv_columns", b"\x00" + SEP.join(cols))
put("frf_merge", "uff_columns", b"\x07" + SEP.join(uff_column(j) for j in (1, 2, 3)))
put("frf_merge", "mixed_columns", b"\x02" + SEP.join([cols[0], uff_column(2), cols[2]]))
put("frf_merge", "duplicate_column", b"\x00" + SEP.join([cols[0], cols[0]]))
put("frf_merge", "other_lines", b"\x00" + SEP.join([cols[0], matrix_csv(["xy", "yy", "zy"], n=3).encode()]))
put("frf_merge", "other_units", b"\x02" + SEP.join([cols[0], uff_column(2).replace(b"N                   ", b"lbf                 ")]))
put("frf_merge", "single", b"\x00" + matrix_csv(ALL9).encode())
