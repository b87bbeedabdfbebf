"""Seeded hostile inputs for the Mitsuba XML reader, its meshes (PLY,
serialized), checkpoints and cluster addresses, for tests/robustness/test_fuzz.py.

Every case is ``(family, target, mutation, seed)``; its bytes come from
``random.Random(case id)`` alone, so a failing id reruns alone with
``pytest tests/robustness/test_fuzz.py -k ID``.

* ``xml/FILE-MUTATION-sSEED``: ``tests/data/xml`` copied, ``FILE`` (the
  meshes scene, its PLY, its serialized meshes, its OBJ) mutated, the scene
  loaded in-process.
* ``checkpoint/MUTATION-sSEED``: a real checkpoint of a 16x16 render,
  mutated, read back by :func:`drpt.distributed.checkpoint.load`.
* ``cluster/address-sSEED`` and ``cluster/server-KIND-sSEED``: a generated
  ``--cluster`` address checked by
  :func:`drpt.distributed.engine.check_address`, and a fake server on
  127.0.0.1 (garbage, HTTP, silent, closing) probed by
  :func:`drpt.distributed.engine.probe` within a deadline.
"""

from __future__ import annotations

import json
import random
import re
import shutil
import socket
import struct
import threading
import zlib
from pathlib import Path

import numpy as np

from . import DATA

XML_DIR = DATA / "xml"
XML_ENTRY = "meshes.xml"

VALUES = ("nan", "inf", "-inf", "1e308", "-1e308", "1e-320", "0", "-1", "1e30", "4294967296",
          "-2147483649", "", "x", "1,2", "0mm", "1e999", "nan, nan, nan")
XML_MUTATIONS = ("value", "delete_element", "dup_element", "nest", "truncate", "random_bytes",
                 "swap_attr", "include_self")
PLY_MUTATIONS = ("index_oob", "count_big", "truncate", "header_garbage", "random_bytes", "ascii_oob")
SERIALIZED_MUTATIONS = ("index_oob", "count_big", "truncate", "flip_compressed", "table", "version")
OBJ_MUTATIONS = ("index_oob", "random_bytes", "truncate")
CHECKPOINT_MUTATIONS = ("truncate", "flip_byte", "meta_value", "meta_drop", "meta_type", "sums_scale",
                        "sums_shape", "sums_dtype", "sums_nonfinite", "next_shift")
SERVER_KINDS = ("garbage", "http", "silent", "close", "huge_frames")


def rng_for(case_id: str) -> random.Random:
    return random.Random(case_id)


#: scenes of tests/data/xml whose XML is mutated (each loaded itself)
XML_SCENES = ("meshes.xml", "bsdfs.xml", "textured.xml", "spot.xml", "lens.xml", "envmap.xml", "checker.xml",
              "crop.xml", "instances.xml", "composites.xml")


def xml_cases(seeds: int = 3) -> list[tuple[str, str, int]]:
    cases = [(XML_ENTRY, m, s) for m in XML_MUTATIONS for s in range(seeds)]
    cases += [(name, m, s) for name in XML_SCENES[1:] for m in ("value", "swap_attr", "delete_element")
              for s in range(seeds)]
    cases += [("wedge.ply", m, s) for m in PLY_MUTATIONS for s in range(seeds)]
    cases += [("shapes.serialized", m, s) for m in SERIALIZED_MUTATIONS for s in range(seeds)]
    cases += [("quad.obj", m, s) for m in OBJ_MUTATIONS for s in range(2)]
    return cases


def xml_id(target: str, mutation: str, seed: int) -> str:
    return f"xml/{target}-{mutation}-s{seed}"


def build_xml(target: str, mutation: str, seed: int, root: Path) -> Path:
    """Copy the XML test scenes to ``root``, mutate ``target``; return the scene to load."""
    for f in XML_DIR.iterdir():
        if f.is_file():
            shutil.copy(f, root / f.name)
    rng = rng_for(xml_id(target, mutation, seed))
    p = root / target
    data = p.read_bytes()
    if target.endswith(".xml"):
        data = mutate_xml(data.decode(), mutation, rng).encode("utf-8", "surrogateescape")
    elif target.endswith(".ply"):
        data = mutate_ply(data, mutation, rng)
    elif target.endswith(".serialized"):
        data = mutate_serialized(data, mutation, rng)
    else:
        data = mutate_obj(data.decode(), mutation, rng).encode()
    p.write_bytes(data)
    return p if target.endswith(".xml") else root / XML_ENTRY


_ATTR = re.compile(r'(value|filename|name|type|x|y|z|angle)="([^"]*)"')
_ELEMENT = re.compile(r"^[ \t]*<(?!/|!|\?)[^\n]*/>[ \t]*\n", re.M)


def mutate_xml(text: str, how: str, rng: random.Random) -> str:
    attrs = list(_ATTR.finditer(text))
    if how == "value":
        m = rng.choice([a for a in attrs if a.group(1) in ("value", "x", "y", "z", "angle")] or attrs)
        return text[:m.start(2)] + rng.choice(VALUES) + text[m.end(2):]
    if how == "swap_attr":
        m = rng.choice(attrs)
        other = rng.choice(attrs)
        return text[:m.start(2)] + other.group(2) + text[m.end(2):]
    lines = list(_ELEMENT.finditer(text))
    if how == "delete_element":
        m = rng.choice(lines)
        return text[:m.start()] + text[m.end():]
    if how == "dup_element":
        m = rng.choice(lines)
        return text[:m.end()] + m.group(0) * rng.randint(1, 3) + text[m.end():]
    if how == "nest":  # deep twosided nesting around a BSDF, at a depth drawn from both sides of the limit
        depth = rng.choice((50, 99, 150, 5000))
        inner = '<bsdf type="diffuse"/>'
        nest = '<bsdf type="twosided">' * depth + inner + "</bsdf>" * depth
        return text.replace("</scene>", f'<shape type="sphere">{nest}</shape>\n</scene>')
    if how == "truncate":
        return text[:rng.randrange(len(text))]
    if how == "random_bytes":
        b = bytearray(text.encode())
        for _ in range(rng.randint(1, 8)):
            b[rng.randrange(len(b))] = rng.randrange(256)
        return b.decode("utf-8", "surrogateescape")
    if how == "include_self":
        return text.replace("</scene>", '<include filename="meshes.xml"/>\n</scene>')
    raise ValueError(how)


def _ply_parts(data: bytes):
    end = data.index(b"end_header\n") + len(b"end_header\n")
    return data[:end].decode(), data[end:]


def mutate_ply(data: bytes, how: str, rng: random.Random) -> bytes:
    head, body = _ply_parts(data)
    counts = {m.group(1): int(m.group(2)) for m in re.finditer(r"element (\w+) (\d+)", head)}
    if how in ("truncate", "random_bytes") or "binary" not in head:
        b = bytearray(data)
        if how == "truncate":
            return bytes(b[:rng.randrange(len(b))])
        for _ in range(rng.randint(1, 8)):
            b[rng.randrange(len(head), len(b))] = rng.randrange(256)
        return bytes(b)
    if how == "header_garbage":
        lines = head.splitlines(True)
        i = rng.randrange(1, len(lines) - 1)
        lines[i] = rng.choice(("property list uchar float x\n", "element face -3\n", "format binary 9\n",
                               "\xff\xfe\n", "property quad y\n", "element vertex 99999999999\n"))
        return "".join(lines).encode("latin-1") + body
    if how == "count_big":
        name = rng.choice(list(counts))
        return head.replace(f"element {name} {counts[name]}",
                            f"element {name} {counts[name] * rng.choice((2, 1000, 1 << 31))}").encode() + body
    if how in ("index_oob", "ascii_oob"):
        # rewrite the mesh with one face index out of range (binary, or ASCII)
        nv = counts["vertex"]
        v = [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0)] + [(rng.random(),) * 3 for _ in range(nv - 3)]
        faces = [(0, 1, 2)] * max(1, counts.get("face", 1))
        bad = rng.choice((nv, nv + 1, 1 << 20, (1 << 31) - 1, -1))
        k = rng.randrange(len(faces))
        faces[k] = (faces[k][0], bad, faces[k][2])
        fmt = "ascii" if how == "ascii_oob" else "binary_little_endian"
        out = (f"ply\nformat {fmt} 1.0\nelement vertex {len(v)}\nproperty float x\nproperty float y\n"
               f"property float z\nelement face {len(faces)}\nproperty list uchar int vertex_indices\n"
               "end_header\n").encode()
        if fmt == "ascii":
            return out + "".join(f"{a} {b} {c}\n" for a, b, c in v).encode() + \
                "".join(f"3 {a} {b} {c}\n" for a, b, c in faces).encode()
        return out + np.asarray(v, "<f4").tobytes() + b"".join(struct.pack("<B3i", 3, *f) for f in faces)
    raise ValueError(how)


def _serialized_shapes(data: bytes) -> list[bytes]:
    """The decompressed records of a version 4 file's shapes."""
    (count,) = struct.unpack_from("<I", data, len(data) - 4)
    offsets = struct.unpack_from(f"<{count}Q", data, len(data) - 4 - 8 * count)
    out = []
    for off in offsets:
        z = zlib.decompressobj()
        out.append(z.decompress(data[off + 4:]))
    return out


def _serialized_file(records: list[bytes], version: int = 4) -> bytes:
    out, offsets = b"", []
    for r in records:
        offsets.append(len(out))
        out += struct.pack("<HH", 0x041C, version) + zlib.compress(r)
    return out + struct.pack(f"<{len(offsets)}Q", *offsets) + struct.pack("<I", len(offsets))


def mutate_serialized(data: bytes, how: str, rng: random.Random) -> bytes:
    if how == "truncate":
        return data[:rng.randrange(len(data))]
    if how == "flip_compressed":
        b = bytearray(data)
        for _ in range(rng.randint(1, 4)):
            b[rng.randrange(4, len(b) - 20)] ^= 1 << rng.randrange(8)
        return bytes(b)
    if how == "table":
        b = bytearray(data)
        b[-4 - rng.randrange(16)] = rng.randrange(256)
        return bytes(b)
    if how == "version":
        return data[:2] + struct.pack("<H", rng.choice((0, 2, 6, 0xFFFF))) + data[4:]
    records = [bytearray(r) for r in _serialized_shapes(data)]
    k = rng.randrange(len(records))
    r = records[k]
    pos = 4 + r.index(b"\0", 4) + 1 - 4  # flags, then the NUL-terminated name
    flags = struct.unpack_from("<I", r)[0]
    v, f = struct.unpack_from("<2Q", r, pos)
    if how == "count_big":
        struct.pack_into("<2Q", r, pos, v * rng.choice((1, 3, 1 << 20)), f * rng.choice((2, 1 << 30, 1 << 40)))
        return _serialized_file([bytes(x) for x in records])
    if how == "index_oob":
        fsize = 8 if flags & 0x2000 else 4
        per = 3 + (3 if flags & 1 else 0) + (2 if flags & 2 else 0) + (3 if flags & 8 else 0)
        faces = pos + 16 + fsize * per * v
        i = rng.randrange(3 * f)
        struct.pack_into("<I", r, faces + 4 * i, rng.choice((v, v + 7, 1 << 20, (1 << 32) - 1)))
        return _serialized_file([bytes(x) for x in records])
    raise ValueError(how)


def mutate_obj(text: str, how: str, rng: random.Random) -> str:
    if how == "index_oob":
        return text + f"\nf 1 2 {rng.choice((9, 1000000, -1000, 2147483648))}\n"
    if how == "truncate":
        return text[:rng.randrange(len(text))]
    b = bytearray(text.encode())
    for _ in range(rng.randint(1, 8)):
        b[rng.randrange(len(b))] = rng.randrange(32, 127)
    return b.decode()


# ------------------------------------------------------------------ checkpoints
def mutate_checkpoint(npz: Path, how: str, rng: random.Random) -> None:
    """Damage the checkpoint ``npz`` in place."""
    raw = npz.read_bytes()
    if how == "truncate":
        npz.write_bytes(raw[:rng.randrange(len(raw))])
        return
    if how == "flip_byte":
        b = bytearray(raw)
        b[rng.randrange(len(b))] ^= 1 << rng.randrange(8)
        npz.write_bytes(bytes(b))
        return
    with np.load(npz) as z:
        s, s2, meta = z["sum"], z["sumsq"], json.loads(str(z["meta"]))
    key = rng.choice(sorted(meta))
    if how == "meta_value":
        meta[key] = rng.choice((None, -1, 0, 1.5, "1", [], {}, True, 10**30, meta.get(key)))
    elif how == "meta_drop":
        del meta[key]
    elif how == "meta_type":
        meta = rng.choice(([1, 2], "x", 3, None))
    elif how == "sums_scale":
        f = rng.choice((-1.0, 0.5, 2.0, 0.0))
        s = s * f
    elif how == "sums_shape":
        h = rng.choice((1, s.shape[0] // 2, s.shape[0] + 1))
        s = np.resize(s, (h, s.shape[1], 3))
        s2 = np.resize(s2, (h, s.shape[1], 3))
    elif how == "sums_dtype":
        t = rng.choice((np.float16, np.float32, np.int64, np.complex128))
        s, s2 = s.astype(t), s2.astype(t)
    elif how == "sums_nonfinite":
        s = s.copy()
        s.flat[rng.randrange(s.size)] = rng.choice((np.nan, np.inf, -np.inf))
    elif how == "next_shift":
        meta["next"] = meta["next"] + rng.choice((-1, 1, 2))
    np.savez(npz, sum=s, sumsq=s2, meta=np.array(json.dumps(meta)))


# ------------------------------------------------------------------ cluster
def address(rng: random.Random) -> str:
    """A ``--cluster`` address, valid or not."""
    scheme = rng.choice(("tcp://", "", "ucx://", "tls://", "inproc://", "ws://", "TCP://", "tcp:/", "://"))
    host = rng.choice(("127.0.0.1", "localhost", "[::1]", "", "a b", "host\nname", "\x00", "é.example",
                       "999.1.1.1"))
    port = rng.choice(("1", "8786", "0", "65536", "-1", "x", "", "99999999999999999999", "1\n2"))
    sep = rng.choice((":", ":", "::", ""))
    return scheme + host + sep + port


class FakeServer:
    """A TCP server on 127.0.0.1 that speaks ``kind`` to whoever connects:
    ``garbage`` (seeded random bytes), ``http`` (an HTTP reply), ``silent``
    (accepts, never answers), ``close`` (accepts and hangs up),
    ``huge_frames`` (a frame header announcing 2^60 bytes)."""

    def __init__(self, kind: str, rng: random.Random):
        self.kind, self.payload = kind, bytes(rng.randrange(256) for _ in range(rng.randint(1, 64)))
        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(4)
        self.sock.settimeout(0.1)
        self.port = self.sock.getsockname()[1]
        self.stop = threading.Event()
        self.conns: list[socket.socket] = []
        self.thread = threading.Thread(target=self._loop, daemon=True)
        self.thread.start()

    def _loop(self):
        while not self.stop.is_set():
            try:
                c, _ = self.sock.accept()
            except OSError:
                continue
            self.conns.append(c)
            try:
                if self.kind == "garbage":
                    c.sendall(self.payload)
                elif self.kind == "http":
                    c.sendall(b"HTTP/1.1 200 OK\r\nContent-Type: text/html\r\n\r\n<html></html>")
                elif self.kind == "close":
                    c.close()
                elif self.kind == "huge_frames":
                    c.sendall(struct.pack("<QQ", 1 << 60, 1))
            except OSError:
                pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.stop.set()
        self.thread.join(2)
        for c in self.conns:
            c.close()
        self.sock.close()
