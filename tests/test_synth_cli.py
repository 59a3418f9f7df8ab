"""``tracker synth --record``: the recorder's settings, reproducible bytes, progress, no overwrite by default."""

import subprocess
import sys

from tracker.cli import main

SMALL = ["--frames", "45", "--size", "240x180"]


def test_the_same_command_twice_writes_the_same_bytes(tmp_path, capsys):
    a, b = tmp_path / "a.mcap", tmp_path / "b.mcap"
    assert main(["synth", "demo", *SMALL, "--record", str(a), "--quiet"]) == 0
    assert main(["synth", "demo", *SMALL, "--record", str(b), "--quiet"]) == 0
    assert a.read_bytes() == b.read_bytes()
    assert main(["replay", str(a), "--check", "--quiet"]) == 0
    # Not an accident of the settings: a live recording of the same frames carries its start time.
    assert b"started_unix_ns" not in a.read_bytes()


def test_an_existing_recording_is_kept_unless_forced(tmp_path, capsys):
    out = tmp_path / "demo.mcap"
    out.write_bytes(b"the committed demo")
    assert main(["synth", "demo", *SMALL, "--record", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "exists" in err and "--force" in err and len(err.strip().splitlines()) == 1
    assert out.read_bytes() == b"the committed demo"
    assert main(["synth", "demo", *SMALL, "--record", str(out), "--quiet", "--force"]) == 0
    assert out.read_bytes().startswith(b"\x89MCAP0\r\n")


def test_out_and_record_together_are_refused(tmp_path, capsys):
    code = main(["synth", "demo", *SMALL, "--record", str(tmp_path / "r.mcap"), "--out", str(tmp_path / "s")])
    assert code == 2
    assert "not allowed with" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []
    assert main(["synth", "demo", *SMALL, "--out", str(tmp_path / "s"), "--zstd-level", "9"]) == 2
    assert main(["synth", "demo", *SMALL, "--record", str(tmp_path / "r.mcap"), "--zstd-level", "99"]) == 2
    assert "--zstd-level: expected -7 to 22, got 99" in capsys.readouterr().err


def test_progress_is_shown_and_help_names_the_frame_pattern(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "tracker", "synth", "demo", *SMALL, "--record",
                           str(tmp_path / "r.mcap")], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "synth [##############################] 45/45 frames 100%" in proc.stderr
    proc = subprocess.run([sys.executable, "-m", "tracker", "synth", "nadir", "--frames", "5", "--out",
                           str(tmp_path / "s")], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0 and "synth [" in proc.stderr and "5/5 frames" in proc.stderr
    helped = subprocess.run([sys.executable, "-m", "tracker", "synth", "--help"], capture_output=True, text=True)
    assert "frames/%05d.png" in helped.stdout and "%%" not in helped.stdout



def test_a_scene_is_never_written_over_another_unless_forced_and_then_wholly(tmp_path, capsys):
    # Written over, a 40-frame scene given 3 new frames kept 37 old ones beside the new truth.
    out = tmp_path / "scene"
    assert main(["synth", "nadir", "--frames", "6", "--size", "160x120", "--out", str(out), "--quiet"]) == 0
    truth = (out / "truth.jsonl").read_bytes()
    capsys.readouterr()
    assert main(["synth", "nadir", "--frames", "3", "--size", "160x120", "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "not empty" in err and "--force" in err and len(err.strip().splitlines()) == 1
    assert len(list((out / "frames").glob("*.png"))) == 6 and (out / "truth.jsonl").read_bytes() == truth
    assert main(["synth", "nadir", "--frames", "3", "--size", "160x120", "--out", str(out), "--quiet",
                 "--force"]) == 0
    assert sorted(p.name for p in (out / "frames").iterdir()) == ["00000.png", "00001.png", "00002.png"]
    assert len((out / "truth.jsonl").read_text().splitlines()) == 3
    # A folder that is not a scene's is not emptied, forced or not.
    (out / "notes.txt").write_text("mine")
    assert main(["synth", "nadir", "--frames", "3", "--size", "160x120", "--out", str(out), "--force"]) == 2
    assert "notes.txt" in capsys.readouterr().err and (out / "notes.txt").read_text() == "mine"
    assert main(["synth", "nadir", "--frames", "0", "--out", str(tmp_path / "none")]) == 2
    assert "--frames: expected at least 1, got 0" in capsys.readouterr().err
    assert not (tmp_path / "none").exists()
