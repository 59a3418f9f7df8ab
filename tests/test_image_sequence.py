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
