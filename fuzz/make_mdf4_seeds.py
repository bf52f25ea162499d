#!/usr/bin/env python3
"""Writes the hand-made seeds of the `mdf4` fuzz target into corpus/mdf4/.

Small MDF 4.10 files that reach the parts of the reader a file written by twinbench (one
group, 64-bit floats, no conversion) does not: several data groups, integer and 32-bit float
channels, conversions (linear, rational, algebraic, value tables, value to text), a data list
behind an `##HL` block, unsorted records with record IDs, an unfinalized file, variable-length
and string channels, invalidation bits. The seed written by twinbench itself
(`twinbench_run.mf4`) is made with `twinbench run` (docs/robustness.md, "Fuzzing").

    python3 make_mdf4_seeds.py     # from fuzz/
"""

import os
import struct


class Mdf:
    def __init__(self, file_id=b"MDF     "):
        self.b = bytearray(file_id + b"4.10    " + b"seeds   " + bytes(4))
        self.b += struct.pack("<H", 410) + bytes(30) + bytes(4)
        assert len(self.b) == 64
        self.hd = self.block(b"##HD", [0] * 6, bytes(32))

    def block(self, kind, links, data=b""):
        while len(self.b) % 8:
            self.b.append(0)
        at = len(self.b)
        self.b += kind + bytes(4) + struct.pack("<QQ", 24 + 8 * len(links) + len(data), len(links))
        self.b += b"".join(struct.pack("<Q", l) for l in links) + data
        return at

    def link(self, block, i, to):
        struct.pack_into("<Q", self.b, block + 24 + 8 * i, to)

    def text(self, s, kind=b"##TX"):
        if not s:
            return 0
        raw = s.encode() + b"\0"
        raw += bytes(-len(raw) % 8)
        return self.block(kind, [], raw)

    def cc(self, kind, values=(), refs=()):
        data = struct.pack("<BBHHH", kind, 0, 0, len(refs), len(values)) + struct.pack("<dd", 0, 0)
        data += b"".join(struct.pack("<d", v) for v in values)
        return self.block(b"##CC", [0, 0, 0, 0, *refs], data)

    def cn(self, name, unit="", cn_type=0, data_type=4, byte_offset=0, bits=64, cc=0,
           data=0, flags=0, inval_bit=0, bit_offset=0):
        fields = struct.pack("<BBBBIIII", cn_type, 2 if cn_type == 2 else 0, data_type,
                             bit_offset, byte_offset, bits, flags, inval_bit)
        fields += struct.pack("<BBH", 0, 0, 0) + bytes(48)
        return self.block(b"##CN", [0, 0, self.text(name), 0, cc, data, self.text(unit), 0],
                          fields)

    def cg(self, channels, cycles, record_bytes, record_id=0, inval_bytes=0):
        data = struct.pack("<QQHHIII", record_id, cycles, 0, 0, 0, record_bytes, inval_bytes)
        at = self.block(b"##CG", [0, 0, 0, 0, 0, 0], data)
        self.chain(at, 1, channels)
        return at

    def dg(self, groups, data_link, record_id_bytes=0):
        at = self.block(b"##DG", [0, 0, data_link, 0], struct.pack("<B", record_id_bytes) + bytes(7))
        self.chain(at, 1, groups)
        return at

    def chain(self, parent, link, items):
        """Links `items` as a chain (each one's link 0 to the next) from `parent`'s `link`."""
        if items:
            self.link(parent, link, items[0])
        for a, b in zip(items, items[1:]):
            self.link(a, 0, b)

    def data_groups(self, dgs):
        self.chain(self.hd, 0, dgs)

    def dt(self, payload):
        return self.block(b"##DT", [], payload)


def records(fmt, rows):
    return b"".join(struct.pack(fmt, *r) for r in rows)


def two_groups():
    m = Mdf()
    # Group 1: time (f64), an unsigned 16-bit LE and a signed 32-bit BE channel.
    rows = [(i * 0.1, i * 3, -i * 1000) for i in range(6)]
    cg1 = m.cg([m.cn("time", "s", cn_type=2), m.cn("n", "rpm", data_type=0, byte_offset=8, bits=16),
                m.cn("torque", "N.m", data_type=3, byte_offset=10, bits=32)], 6, 14)
    dg1 = m.dg([cg1], m.dt(b"".join(struct.pack("<dH", t, n) + struct.pack(">i", q)
                                    for t, n, q in rows)))
    # Group 2: a 32-bit float time base at another rate and a 4-bit field at bit offset 2.
    rows2 = [(i * 0.25, 1.5 * i, (i % 16) << 2) for i in range(4)]
    cg2 = m.cg([m.cn("time", "s", cn_type=2, data_type=4, bits=32),
                m.cn("v", "km/h", data_type=4, byte_offset=4, bits=32),
                m.cn("gear", "", data_type=0, byte_offset=8, bits=4, bit_offset=2)], 4, 9)
    dg2 = m.dg([cg2], m.dt(records("<ffB", rows2)))
    m.data_groups([dg1, dg2])
    return m.b


def conversions():
    m = Mdf()
    lin = m.cc(1, [10.0, 0.5])
    rat = m.cc(2, [0, 1, 0, 0, 0, 1])
    alg = m.cc(3, [], [m.text("X*2+(X-1)^2/3")])
    tab = m.cc(4, [0, 0, 10, 100, 20, 400])
    rng = m.cc(6, [0, 5, 1, 5, 10, 2, -1])
    v2t = m.cc(7, [1, 2], [m.text("one"), m.text("two"), m.text("other")])
    chans = [m.cn("time", "s", cn_type=2)]
    for i, (name, cc) in enumerate([("lin", lin), ("rat", rat), ("alg", alg), ("tab", tab),
                                    ("rng", rng), ("state", v2t)]):
        chans.append(m.cn(name, "", data_type=0, byte_offset=8 + 2 * i, bits=16, cc=cc))
    rows = [struct.pack("<d", i * 0.01) + struct.pack("<6H", *([i] * 6)) for i in range(8)]
    m.data_groups([m.dg([m.cg(chans, 8, 20)], m.dt(b"".join(rows)))])
    return m.b


def data_list():
    m = Mdf()
    part = [records("<dd", [(i * 0.1 + k, i + 10 * k) for i in range(4)]) for k in range(2)]
    dts = [m.dt(p) for p in part]
    dl = m.block(b"##DL", [0, *dts], struct.pack("<B3xIQ", 1, 2, len(part[0])))
    hl = m.block(b"##HL", [dl], struct.pack("<HB5x", 0, 0))
    cg = m.cg([m.cn("time", "s", cn_type=2), m.cn("x", "m", byte_offset=8)], 8, 16)
    m.data_groups([m.dg([cg], hl)])
    return m.b


def unsorted():
    m = Mdf()
    a = m.cg([m.cn("time", "s", cn_type=2), m.cn("a", "V", data_type=4, byte_offset=8, bits=32)],
             3, 12, record_id=1)
    b = m.cg([m.cn("time", "s", cn_type=2), m.cn("b", "A", data_type=2, byte_offset=8, bits=8)],
             2, 9, record_id=2)
    data = b""
    for i in range(3):
        data += struct.pack("<Bdf", 1, i * 0.5, i * 1.25)
        if i < 2:
            data += struct.pack("<Bdb", 2, i * 0.7, -i)
    m.data_groups([m.dg([a, b], m.dt(data), record_id_bytes=1)])
    return m.b


def unfinalized():
    m = Mdf(b"UnFinMF ")
    cg = m.cg([m.cn("time", "s", cn_type=2), m.cn("y", "", byte_offset=8)], 0, 16)
    dg = m.dg([cg], 0)
    m.data_groups([dg])
    # The last block: a data block of 24 bytes whose records run to the end of the file.
    m.link(dg, 2, m.block(b"##DT", []))
    m.b += records("<dd", [(i * 0.2, i * i) for i in range(5)])
    return m.b


def vlsd_and_strings():
    m = Mdf()
    sd_data = b"".join(struct.pack("<I", len(s)) + s for s in [b"ab", b"", b"xyz"])
    sd = m.block(b"##SD", [], sd_data)
    chans = [m.cn("time", "s", cn_type=2),
             m.cn("label", "", cn_type=1, data_type=7, byte_offset=8, bits=64, data=sd),
             m.cn("code", "", data_type=6, byte_offset=16, bits=32),
             # Invalid when bit 0 of the invalidation byte is set.
             m.cn("maybe", "", data_type=0, byte_offset=20, bits=8, flags=2, inval_bit=0)]
    rows = [struct.pack("<dQ4sBB", i * 0.1, 0, b"ab%d " % i, i, i % 2) for i in range(3)]
    m.data_groups([m.dg([m.cg(chans, 3, 21, inval_bytes=1)], m.dt(b"".join(rows)))])
    return m.b


if __name__ == "__main__":
    out = os.path.join(os.path.dirname(os.path.abspath(__file__)), "corpus", "mdf4")
    os.makedirs(out, exist_ok=True)
    for f in [two_groups, conversions, data_list, unsorted, unfinalized, vlsd_and_strings]:
        with open(os.path.join(out, f.__name__ + ".mf4"), "wb") as fh:
            fh.write(f())
