"""Register map, encoding and block contents, against hand-computed values and the contract text."""

from __future__ import annotations

import itertools
import re
from pathlib import Path

import numpy as np
import pytest

from plc.block import BlockBuilder, Pose, ms_u32, select_object
from plc.encode import (
    WordOrder,
    decode_block,
    decode_f32,
    decode_u32,
    encode_block,
    encode_f32,
    encode_u32,
)
from plc.options import PlcOptions, backoff_delays, parse_endpoint
from plc.registers import BLOCK_WORDS, FIELDS, REGISTER_MAP
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


def test_map_matches_the_contract_table():
    if not CONTRACT.is_file():
        pytest.skip(f"{CONTRACT} not present (the shared contract is outside the repository)")
    text = CONTRACT.read_text(encoding="utf-8").split("## 4.")[1]
    rows = re.findall(r"^\| (\d+(?:-\d+)?) \| ([a-z0-9 x]+?) \| (\w+) \|", text, flags=re.M)
    assert len(rows) == len(REGISTER_MAP)
    for (addr, typ, name), f in zip(rows, REGISTER_MAP, strict=True):
        assert (addr, typ, name) == (f.addresses, f.type_text, f.name)
    assert BLOCK_WORDS == 43


def test_block_layout_hand_checked():
    values = {f.name: 0 for f in REGISTER_MAP} | {"corners_mm": [0.0] * 8}
    values |= {"heartbeat": 7, "seq": 0x00010002, "x_mm": 1.0, "corners_mm": [0.0] * 7 + [-2.5], "measured": 1}
    regs = encode_block(values, ABCD)
    assert len(regs) == 43
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


def test_block_reports_the_oldest_track_and_counts_poses():
    b = BlockBuilder(ABCD)
    health = Health()
    idle = b.prepare(None, health, True, 1000)
    assert idle.values["seq"] == 0 and idle.values["count"] == 0 and idle.values["heartbeat"] == 1
    assert idle.values["status"] == 0b10111  # running, camera ok, calibration, recording ok; no part
    b.commit(idle)

    p = b.prepare(Pose(900, (_obj(5, 100.0), _obj(3, 50.0, measured=False))), health, True, 1001)
    v = p.values
    assert (v["id"], v["x_mm"], v["measured"], v["count"], v["seq"]) == (3, 50.0, 0, 2, 1)
    assert v["status"] & (1 << 3) and v["t_capture_ms"] == 900 and v["t_write_ms"] == 1001
    assert decode_block(p.registers, ABCD)["y_mm"] == np.float32(0.1235)  # the pose stream's rounded value
    # Not committed (the write failed): the next block is still seq 1.
    again = b.prepare(Pose(910, (_obj(3, 51.0),)), health, True, 1002)
    assert again.values["seq"] == 1 and again.values["heartbeat"] == 2
    b.commit(again)

    empty = b.prepare(Pose(920, ()), health, True, 1003)
    ev = empty.values
    assert (ev["count"], ev["seq"], ev["x_mm"], ev["id"], ev["t_capture_ms"]) == (0, 1, 51.0, 3, 910)
    assert not ev["status"] & (1 << 3)
    b.commit(empty)
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
    p = b.prepare(Pose(0, (_obj(1, 0.0),)), Health(), True, 0)
    assert p.values["heartbeat"] == 0 and p.values["seq"] == 0


def test_ms_clock_wraps_at_32_bits():
    assert ms_u32(5_999_999) == 5
    assert ms_u32((2**32 + 7) * 1_000_000) == 7


def test_selection_is_lowest_id():
    assert select_object((_obj(9, 0.0), _obj(2, 5.0), _obj(4, 9.0))).id == 2


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
                                            ({"base": -1}, "--plc-base"), ({"base": 65536 - 42}, "--plc-base")])
def test_options_reject_bad_unit_and_base(kw, needle):
    with pytest.raises(BadInput, match=needle):
        PlcOptions("127.0.0.1", 502, **kw)
    assert PlcOptions("127.0.0.1", 502, base=65536 - 43).base == 65493  # the last base that fits


def test_backoff_doubles_and_caps_at_two_seconds():
    opts = PlcOptions("h", 1)
    assert list(itertools.islice(backoff_delays(opts.backoff_first_s, opts.backoff_max_s), 7)) == [
        0.1, 0.2, 0.4, 0.8, 1.6, 2.0, 2.0]


def test_fields_index_by_name():
    assert (FIELDS["seq"].address, FIELDS["corners_mm"].words, FIELDS["measured"].address) == (4, 16, 42)
