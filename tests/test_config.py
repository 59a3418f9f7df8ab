"""Bad settings files: one line naming the setting and what it should be, exit 2, before any input opens."""

import json

import pytest

from tracker.cli import main


@pytest.mark.parametrize("content,needle", [
    (b"\xff\xfe\x00binary", "UTF-8"),
    (b"[" * 100000 + b"]" * 100000, "nested"),
    (json.dumps({"segment": {"diff_threshold": True}}).encode(), "segment.diff_threshold: expected an integer"),
    (json.dumps({"segment": {"diff_threshold": 2.5}}).encode(), "segment.diff_threshold: expected an integer"),
    (json.dumps({"track": {"gate_mm": None}}).encode(), "track.gate_mm: expected a finite number"),
    (json.dumps({"track": {"height_unconverged_sigma_mm": 0.2}}).encode(),
     "track.height_unconverged_sigma_mm: expected >= height_converged_sigma_mm (0.3), got 0.2"),
    (json.dumps({"track": {"flat_check_views": 2}}).encode(), "track.flat_check_views: expected at least 3 views"),
    (json.dumps({"measure": {"model_sigma_px": -0.01}}).encode(), "measure.model_sigma_px: expected >= 0, got -0.01"),
    (json.dumps({"measure": {"smooth_texture_ratio": -1}}).encode(),
     "measure.smooth_texture_ratio: expected >= 0, got -1"),
    (json.dumps({"bogus": {}}).encode(), "unknown sections"),
    (json.dumps({"segment": 3}).encode(), "segment: expected an object"),
    (json.dumps([1]).encode(), "expected a JSON object"),
])
def test_bad_config(tmp_path, capsys, content, needle):
    f = tmp_path / "c.json"
    f.write_bytes(content)
    assert main(["run", "--source", "x.avi", "--calibration", "nope.yaml", "--config", str(f), "--no-plc"]) == 2
    err = capsys.readouterr().err
    assert needle in err and "Traceback" not in err and err.count("\n") == 1
