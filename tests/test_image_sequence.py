"""An image sequence as a source: where it ends, and a gap in it."""

from tracker.cli import main


def test_an_image_sequence_with_a_gap_stops_there_naming_the_missing_file(scene_dir, tmp_path, capsys):
    frames = tmp_path / "frames"
    frames.mkdir()
    for src in sorted((scene_dir / "frames").glob("*.png"))[:20]:
        if src.name != "00012.png":
            (frames / src.name).symlink_to(src)
    poses = tmp_path / "p.jsonl"
    args = ["run", "--source", str(frames / "%05d.png"), "--calibration", str(scene_dir / "calibration.yaml"),
            "--fps", "30", "--no-plc", "--quiet", "--poses", str(poses)]
    assert main(args) == 1
    err = capsys.readouterr().err
    assert "00012.png: missing from the image sequence" in err and "00013.png follows" in err
    assert len(poses.read_text().splitlines()) == 12  # the frames before the gap were tracked
    # Its end is an end: the last file missing is no gap.
    (frames / "00012.png").symlink_to(scene_dir / "frames" / "00012.png")
    assert main(args) == 0
    assert len(poses.read_text().splitlines()) == 20


def test_a_bad_frame_after_the_first_stops_the_run_with_exit_1_and_keeps_what_came_before(scene_dir, tmp_path,
                                                                                           capsys):
    # Exit 2 says "bad input, nothing written": by frame 10 the outputs hold ten frames, so a frame that
    # cannot be read, or of another size, there is exit 1 (as a camera lost mid-run), and says so.
    import cv2
    import numpy as np

    frames = tmp_path / "frames"
    frames.mkdir()
    for src in sorted((scene_dir / "frames").glob("*.png"))[:20]:
        (frames / src.name).symlink_to(src)
    poses, record = tmp_path / "p.jsonl", tmp_path / "r.mcap"
    args = ["run", "--source", str(frames / "%05d.png"), "--calibration", str(scene_dir / "calibration.yaml"),
            "--fps", "30", "--no-plc", "--quiet", "--poses", str(poses), "--record", str(record)]
    bad = frames / "00010.png"
    for content in (b"junk", None):
        bad.unlink()
        if content is None:
            assert cv2.imwrite(str(bad), np.zeros((240, 320), np.uint8))
        else:
            bad.write_bytes(content)
        assert main(args) == 1
        err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
        assert len(err) == 1 and "after 10 frames" in err[0], err
        assert ("00010.png: cannot read the image" if content else "frame 10: frame is 320x240") in err[0], err
        assert [int(line.split(",")[0].split(":")[1]) for line in poses.read_text().splitlines()] == list(range(10))
        assert main(["replay", str(record), "--check"]) == 0
        capsys.readouterr()
