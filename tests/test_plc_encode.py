"""Register map, encoding and block contents, against hand-computed values and the contract text."""

from __future__ import annotations

import itertools
import re
from pathlib import Path

import numpy as np
import pytest

from plc.block import BlockBuilder, Pose, ms_u32
from plc.encode import (
    WordOrder,
    decode_block,
    decode_f32,
    decode_queue,
    decode_u32,
    encode_block,
    encode_f32,
    encode_queue,
    encode_u32,
)
from plc.options import PlcOptions, backoff_delays, parse_endpoint
from plc.queue import PickOrder, entry_fields
from plc.registers import (
    BLOCK_WORDS,
    ENTRY_MAP,
    ENTRY_START,
    FIELDS,
    QUEUE_HEADER,
    QUEUE_WORDS,
    REGISTER_MAP,
    TAKEN,
)
from tracker.errors import BadInput
from tracker.health import FAULT_RECORDING, Health
from tracker.poses import TrackedObject

ABCD, CDAB = WordOrder.ABCD, WordOrder.CDAB
CONTRACT = Path(__file__).resolve().parents[2] / "shared" / "CONTRACT.md"


@pytest.mark.parametrize(("value", "abcd"), [
    (1.0, [0x3F80, 0x0000]),
    (-2.5, [0xC020, 0x0000]),
    (0.1, [0x3DCC, 0xCCCD]),  # float32(0.1) = 0x3DCCCCCD
    (300.0, [0x4396, 0x0000]),
    (-0.0, [0x8000, 0x0000]),
])
def test_float32_both_word_orders(value, abcd):
    assert encode_f32(value, ABCD) == abcd
    assert encode_f32(value, CDAB) == abcd[::-1]
    assert decode_f32(abcd, ABCD) == np.float32(value)
    assert decode_f32(abcd[::-1], CDAB) == np.float32(value)


@pytest.mark.parametrize(("value", "abcd"), [
    (0, [0, 0]), (1, [0x0000, 0x0001]), (65536, [0x0001, 0x0000]),
    (123456789, [0x075B, 0xCD15]), (0xFFFFFFFF, [0xFFFF, 0xFFFF]),
])
def test_uint32_both_word_orders(value, abcd):
    assert encode_u32(value, ABCD) == abcd
    assert encode_u32(value, CDAB) == abcd[::-1]
    assert decode_u32(abcd, ABCD) == value
    assert decode_u32(abcd[::-1], CDAB) == value


@pytest.mark.parametrize("bad", [-1, 2**32])
def test_uint32_out_of_range_is_refused(bad):
    with pytest.raises(ValueError, match="uint32"):
        encode_u32(bad)


def test_non_finite_float_is_refused():
    with pytest.raises(ValueError, match="finite"):
        encode_f32(float("nan"))


ROW = r"^\| (\d+(?:-\d+)?) \| ([a-z0-9 x]+?) \| (\w+) \|(.*)\|$"


def _contract() -> str:
    if not CONTRACT.is_file():
        pytest.skip(f"{CONTRACT} not present (the shared contract is outside the repository)")
    return CONTRACT.read_text(encoding="utf-8")


def test_map_matches_the_contract_table():
    text = _contract().split("## 4.")[1].split("### 4b.")[0]
    rows = re.findall(ROW, text, flags=re.M)
    assert len(rows) == len(REGISTER_MAP)
    for (addr, typ, name, _), f in zip(rows, REGISTER_MAP, strict=True):
        assert (addr, typ, name) == (f.addresses, f.type_text, f.name)
    assert BLOCK_WORDS == 45
    # The fault codes' texts, with the contract's explanations in parentheses.
    fault = dict((r[2], r[3].strip()) for r in rows)["fault"]
    assert fault == FIELDS["fault"].meaning


def test_queue_map_matches_the_contract_section_4b():
    text = _contract().split("### 4b.")[1].split("\n## ")[0]
    rows = re.findall(ROW, text, flags=re.M)
    assert [(a, t, n) for a, t, n, _ in rows] == [(f.addresses, f.type_text, f.name) for f in QUEUE_HEADER]
    assert re.search(r"^\| 110 \+ 22k \| \| entry k \(k = 0\.\.4\) \| 22 registers each, 110-131, 132-153, "
                     r"154-175, 176-197, 198-219 \|", text, flags=re.M)
    assert ENTRY_START == 110 and QUEUE_WORDS == 120
    # "o+0-1 uint32 `id`, o+2-3 float32 `x_mm`, ..., o+21 reserved (0)"
    entry = re.findall(r"o\+(\d+(?:-\d+)?)\s+(uint16|uint32|float32)\s+`(\w+)`", text)
    entry.append(re.search(r"o\+(\d+)\s+(reserved)", text).groups() + ("reserved",))
    assert [(a, t if t != "reserved" else "uint16", n) for a, t, n in entry] == [
        (f.addresses, f.type_text, f.name) for f in ENTRY_MAP]
    assert "bit 0: not pickable" in text and "bit 1: height not yet" in text
    m = re.search(r"registers (\d+)-(\d+) \((uint32) `(taken_id)`\)", text)
    assert m.groups() == (TAKEN.addresses.split("-")[0], str(TAKEN.last), TAKEN.type_text, TAKEN.name)


def test_block_layout_hand_checked():
    values = {f.name: 0 for f in REGISTER_MAP} | {"corners_mm": [0.0] * 8}
    values |= {"heartbeat": 7, "seq": 0x00010002, "x_mm": 1.0, "corners_mm": [0.0] * 7 + [-2.5], "measured": 1}
    values["height_mm"] = 0.1
    regs = encode_block(values, ABCD)
    assert len(regs) == 45
    assert regs[43:45] == [0x3DCC, 0xCCCD]
    assert regs[0] == 7
    assert regs[4:6] == [0x0001, 0x0002]
    assert regs[12:14] == [0x3F80, 0x0000]
    assert regs[40:42] == [0xC020, 0x0000]  # y3, the last corner value
    assert regs[42] == 1
    swapped = encode_block(values, CDAB)
    assert swapped[4:6] == [0x0002, 0x0001] and swapped[12:14] == [0x0000, 0x3F80]
    assert decode_block(swapped, CDAB)["corners_mm"][7] == -2.5


def _obj(track_id: int, x: float, measured: bool = True) -> TrackedObject:
    corners = np.array([[x - 40, -25], [x + 40, -25], [x + 40, 25], [x - 40, 25]], dtype=float)
    return TrackedObject(track_id, x, 0.123456, 12.5, 80.0, 50.0, corners, 300.0, -0.5, measured)


def test_block_reports_the_given_first_entry_and_counts_poses():
    b = BlockBuilder(ABCD)
    health = Health()
    idle = b.prepare(None, health, True, 1000)
    assert idle.values["seq"] == 0 and idle.values["count"] == 0 and idle.values["heartbeat"] == 1
    assert idle.values["status"] == 0b10111  # running, camera ok, calibration, recording ok; no part
    b.commit(idle)

    objects = (_obj(5, 100.0), _obj(3, 50.0, measured=False))
    p = b.prepare(Pose(900, objects), health, True, 1001, objects[1])
    v = p.values
    assert (v["id"], v["x_mm"], v["measured"], v["count"], v["seq"]) == (3, 50.0, 0, 2, 1)
    assert v["status"] & (1 << 3) and v["t_capture_ms"] == 900 and v["t_write_ms"] == 1001
    assert decode_block(p.registers, ABCD)["y_mm"] == np.float32(0.1235)  # the pose stream's rounded value
    # Not committed (the write failed): the next block is still seq 1.
    again = b.prepare(Pose(910, (_obj(3, 51.0),)), health, True, 1002, _obj(3, 51.0))
    assert again.values["seq"] == 1 and again.values["heartbeat"] == 2
    b.commit(again)

    empty = b.prepare(Pose(920, ()), health, True, 1003)
    ev = empty.values
    assert (ev["count"], ev["seq"], ev["x_mm"], ev["id"], ev["t_capture_ms"]) == (0, 1, 51.0, 3, 910)
    assert not ev["status"] & (1 << 3)
    b.commit(empty)
    # Parts tracked but none listed (all taken): the queue is empty, so count 0, object kept, seq unchanged.
    all_taken = b.prepare(Pose(930, (_obj(7, 9.0),)), health, True, 1004, None)
    assert (all_taken.values["count"], all_taken.values["seq"], all_taken.values["id"]) == (0, 1, 3)
    beat = b.prepare(None, health, True, 1004)
    assert beat.values["count"] == 0 and beat.values["heartbeat"] == empty.values["heartbeat"] + 1


def test_status_and_fault_words_tell_the_truth():
    health = Health(camera_ok=False, recording_ok=False)
    health.set_fault(FAULT_RECORDING)
    v = BlockBuilder(ABCD).prepare(None, health, False, 0).values
    assert v["status"] == (1 << 2) | (1 << 15)  # only "calibration loaded" and "fault"
    assert v["fault"] == FAULT_RECORDING


def test_heartbeat_and_seq_wrap():
    b = BlockBuilder(ABCD)
    b.state = type(b.state)(heartbeat=0xFFFF, seq=0xFFFFFFFF)
    p = b.prepare(Pose(0, (_obj(1, 0.0),)), Health(), True, 0, _obj(1, 0.0))
    assert p.values["heartbeat"] == 0 and p.values["seq"] == 0


def test_ms_clock_wraps_at_32_bits():
    assert ms_u32(5_999_999) == 5
    assert ms_u32((2**32 + 7) * 1_000_000) == 7


def _moving(track_id: int, x: float, y: float, vx: float, vy: float) -> TrackedObject:
    corners = np.array([[x - 4, y - 2], [x + 4, y - 2], [x + 4, y + 2], [x - 4, y + 2]], dtype=float)
    return TrackedObject(track_id, x, y, 0.0, 8.0, 4.0, corners, vx, vy, True)


@pytest.mark.parametrize(("v", "expected"), [
    ((300.0, 0.0), [4, 2, 9]),  # +X: largest x first
    ((-300.0, 0.0), [9, 2, 4]),  # -X: smallest x first
    ((0.0, 250.0), [2, 9, 4]),  # +Y: largest y first (9 and 2 level: the older track first)
    ((212.0, -212.0), [4, 2, 9]),  # diagonal: x - y largest first (4: 90, 2: 30, 9: -20)
])
def test_pick_order_is_downstream_first_along_the_motion(v, expected):
    objs = (_moving(9, 0.0, 20.0, *v), _moving(2, 50.0, 20.0, *v), _moving(4, 100.0, 10.0, *v))
    order = PickOrder(min_speed_mm_s=5.0)
    assert [o.id for o in order.order(objs)] == expected
    assert [o.id for o in order.order(objs, taken={expected[0]})] == expected[1:]
    # A frame of new tracks (velocity 0 at birth) keeps the belt direction learned before.
    still = tuple(_moving(o.id, o.x_mm, o.y_mm, 0.0, 0.0) for o in objs)
    assert [o.id for o in order.order(still)] == expected


def test_pick_order_before_anything_moves_is_oldest_first():
    objs = (_moving(9, 100.0, 0.0, 0.0, 0.0), _moving(2, 0.0, 0.0, 1.0, 0.0), _moving(4, 50.0, 0.0, 0.0, 0.0))
    assert [o.id for o in PickOrder(5.0).order(objs)] == [2, 4, 9]


def test_queue_layout_hand_checked_both_word_orders():
    import dataclasses
    a = dataclasses.replace(_moving(7, 1.0, -2.5, 300.0, 0.0), height_mm=0.1, age_frames=3, pickable=False,
                            measured=False)
    b = dataclasses.replace(_moving(70000, 2.0, 0.0, 0.0, 0.0), height_converged=False, age_frames=70000)
    header = {"queue_seq": 0x00010002, "queue_count": 2, "in_view": 6, "t_capture_ms": 5, "taken_echo": 65536,
              "t_write_ms": 9}
    regs = encode_queue(header, [entry_fields(a), entry_fields(b)], ABCD)
    assert len(regs) == 120
    assert regs[0:10] == [1, 2, 2, 6, 0, 5, 1, 0, 0, 9]
    e0 = regs[10:32]
    assert e0[0:2] == [0, 7] and e0[2:4] == [0x3F80, 0] and e0[4:6] == [0xC020, 0]
    assert e0[8:10] == [0x4396, 0] and e0[16:18] == [0x3DCC, 0xCCCD]
    assert e0[18:22] == [0, 3, 0b01, 0]  # predicted, 3 frames old, not pickable, reserved 0
    e1 = regs[32:54]
    assert e1[0:2] == [1, 70000 - 65536] and e1[18:22] == [1, 0xFFFF, 0b10, 0]  # age saturates; height flag
    assert regs[54:] == [0] * 66, "entries past queue_count are all zero"
    swapped = encode_queue(header, [entry_fields(a), entry_fields(b)], CDAB)
    assert swapped[0:2] == [2, 1] and swapped[10:12] == [7, 0] and swapped[12:14] == [0, 0x3F80]
    q = decode_queue(swapped, CDAB)
    assert q["queue_seq"] == 0x00010002 and q["taken_echo"] == 65536
    assert [e["id"] for e in q["entries"]] == [7, 70000] and q["entries"][0]["y_mm"] == -2.5
    with pytest.raises(ValueError, match="at most 5"):
        encode_queue(header, [entry_fields(a)] * 6, ABCD)


@pytest.mark.parametrize(("text", "expected"), [
    ("192.168.0.10:502", ("192.168.0.10", 502)), ("plc.local:5020", ("plc.local", 5020)), ("[::1]:502", ("::1", 502)),
])
def test_parse_endpoint(text, expected):
    assert parse_endpoint(text) == expected


@pytest.mark.parametrize(("text", "needle"), [
    ("192.168.0.10", "HOST:PORT"), (":502", "HOST:PORT"), ("host:", "HOST:PORT"), ("host:abc", "numeric port"),
    ("host:0", "1-65535"), ("host:70000", "1-65535"), ("::1:502", "brackets"),
])
def test_parse_endpoint_rejects(text, needle):
    with pytest.raises(BadInput, match=needle):
        parse_endpoint(text)


@pytest.mark.parametrize(("kw", "needle"), [({"unit": 256}, "--plc-unit"), ({"unit": -1}, "--plc-unit"),
                                            ({"base": -1}, "--plc-base"), ({"base": 65536 - 299}, "--plc-base")])
def test_options_reject_bad_unit_and_base(kw, needle):
    with pytest.raises(BadInput, match=needle):
        PlcOptions("127.0.0.1", 502, **kw)
    assert PlcOptions("127.0.0.1", 502, base=65536 - 300).base == 65236  # the last base where 0-299 fits


def test_backoff_doubles_and_caps_under_two_seconds():
    # The README promises a reconnect within 2 s of the PLC coming back: one wait plus one connect.
    opts = PlcOptions("h", 1)
    assert list(itertools.islice(backoff_delays(opts.backoff_first_s, opts.backoff_max_s), 7)) == [
        0.1, 0.2, 0.4, 0.8, 1.5, 1.5, 1.5]


def test_fields_index_by_name():
    assert (FIELDS["seq"].address, FIELDS["corners_mm"].words, FIELDS["measured"].address) == (4, 16, 42)
