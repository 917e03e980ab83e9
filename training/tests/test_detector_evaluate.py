"""The evaluation CLI on a renderer-like folder (our JSON + calibration), on a YOLO folder as
real data sets come (data.yaml names, unknown_cone ignored), shifted frames, and unlabelled
frames: metrics JSON, annotated PNGs, counts per frame."""

import json

import cv2
import numpy as np
import pytest
from detector_setup import tiny_run

from conesight_train.detector.data import RendererFrames, ToyFrames
from conesight_train.detector.evaluate import main, shift_frame
from conesight_train.detector.train import train


def write_renderer_folder(root, count):
    """Toy frames in the renderer's layout (images/, annotations/, camera_info/, extrinsics/)."""
    for d in ("images", "annotations", "camera_info", "extrinsics"):
        (root / d).mkdir(parents=True)
    for i in range(count):
        frame = ToyFrames(count, seed=7)[i]
        stem = f"{i:06d}"
        cv2.imwrite(str(root / f"images/{stem}.png"), frame.image_rgb[:, :, ::-1])
        cones = [
            {
                "class_id": int(c),
                "bbox": dict(
                    zip(
                        ("x_min_px", "y_min_px", "x_max_px", "y_max_px"),
                        (b - 0.5).tolist(),
                        strict=True,
                    )
                ),
                "range_m": float(r),
                "occlusion": 0.0,
            }
            for b, c, r in zip(frame.boxes_px, frame.classes, frame.range_m, strict=True)
        ]
        record = {"image": f"images/{stem}.png", "cones": cones}
        (root / f"annotations/{stem}.json").write_text(json.dumps(record))
        (root / f"camera_info/{stem}.yaml").write_text(
            "camera_matrix:\n  data: [260.0, 0.0, 128.0, 0.0, 260.0, 40.0, 0.0, 0.0, 1.0]\n"
        )
        (root / f"extrinsics/{stem}.yaml").write_text(
            "vehicle_from_camera: {height_m: 1.0, pitch_down_rad: 0.0}\n"
        )


def test_evaluate_labelled_and_unlabelled(tmp_path):
    data = tmp_path / "sim"
    write_renderer_folder(data, 3)
    frame = RendererFrames(data)[0]
    assert frame.ground is not None and len(frame.boxes_px) > 0
    config = tiny_run(str(data), str(data), tmp_path / "run")
    train(config, progress=False)
    out = tmp_path / "eval.json"
    main(
        [
            "--checkpoint",
            str(tmp_path / "run/last.pt"),
            "--data",
            str(data),
            "--json",
            str(out),
            "--png",
            str(tmp_path / "png"),
            "--png-count",
            "2",
        ]
    )
    report = json.loads(out.read_text())
    assert report["frames"] == 3
    assert sum(row["truths"] for row in report["per_class"].values()) > 0
    assert set(report["recall_by_range"]) == {"0-10 m", "10-20 m", "20-30 m", ">= 30 m"}
    assert set(report["recall_by_height"]) == {"0-20 px", "20-40 px", ">= 40 px"}
    assert sorted(p.name for p in (tmp_path / "png").iterdir()) == ["000000.png", "000001.png"]
    out = tmp_path / "counts.json"
    main(
        [
            "--checkpoint",
            str(tmp_path / "run/last.pt"),
            "--images",
            str(data / "images"),
            "--json",
            str(out),
        ]
    )
    counts = json.loads(out.read_text())["counts"]
    assert set(counts) == {"000000", "000001", "000002"}
    assert all(
        c["total"] == sum(c[n] for n in ("blue", "yellow", "orange", "large_orange"))
        for c in counts.values()
    )
    assert np.isfinite(report["recall"])


def write_yolo_split(root, count):
    """Toy frames as a Roboflow YOLO export: split/images, split/labels, data.yaml above, FSOCO
    class names in FSOCO's order, one cone per frame relabelled unknown_cone."""
    split = root / "test"
    (split / "images").mkdir(parents=True)
    (split / "labels").mkdir()
    (root / "data.yaml").write_text(
        "names: ['blue_cone', 'large_orange_cone', 'orange_cone', 'unknown_cone', 'yellow_cone']\n"
    )
    ours_to_fsoco = {0: 0, 1: 4, 2: 2, 3: 1}
    for i in range(count):
        frame = ToyFrames(count, seed=11)[i]
        h, w = frame.image_rgb.shape[:2]
        cv2.imwrite(str(split / f"images/f{i}.jpg"), frame.image_rgb[:, :, ::-1])
        lines = []
        for k, (b, c) in enumerate(zip(frame.boxes_px, frame.classes, strict=True)):
            cls = 3 if k == 0 else ours_to_fsoco[int(c)]
            cx, cy = (b[0] + b[2]) / 2 / w, (b[1] + b[3]) / 2 / h
            lines.append(f"{cls} {cx:.6f} {cy:.6f} {(b[2] - b[0]) / w:.6f} {(b[3] - b[1]) / h:.6f}")
        (split / f"labels/f{i}.txt").write_text("\n".join(lines) + "\n")
    return split


def test_yolo_folders_map_names_and_ignore_unknown_cones(tmp_path):
    from conesight_train.detector.real_frames import YoloFrames, open_real

    split = write_yolo_split(tmp_path / "ds", 2)
    frames = YoloFrames(split)
    toy = ToyFrames(2, seed=11)[1]
    frame = frames[1]
    assert frame.classes[0] == -1 and frame.difficult_mask()[0]
    np.testing.assert_array_equal(frame.classes[1:], toy.classes[1:])
    np.testing.assert_allclose(frame.boxes_px, toy.boxes_px, atol=0.01)
    assert isinstance(open_real(f"yolo:{split}"), YoloFrames)
    (tmp_path / "ds/data.yaml").write_text("names: ['blue_cone', 'traffic_light']\n")
    with pytest.raises(Exception, match="traffic_light"):
        YoloFrames(split)


def test_shifted_frames_keep_their_cones_on_the_boxes():
    frame = ToyFrames(1, seed=5, cones_per_frame=6)[0]
    for fraction in (0.25, -0.25):
        moved = shift_frame(frame, fraction)
        assert moved.image_rgb.shape == frame.image_rgb.shape
        dy = round(fraction * frame.image_rgb.shape[0])
        for box in moved.boxes_px:
            (k,) = np.nonzero(
                np.all(np.abs(frame.boxes_px[:, [0, 2]] - box[[0, 2]]) < 1e-9, axis=1)
            )[:1]
            if len(k) and box[1] > 0 and box[3] < moved.image_rgb.shape[0]:
                np.testing.assert_allclose(box[[1, 3]], frame.boxes_px[k[0], [1, 3]] + dy)


def test_evaluate_a_yolo_split_with_a_shift(tmp_path):
    split = write_yolo_split(tmp_path / "ds", 3)
    config = tiny_run(f"yolo:{split}", f"yolo:{split}", tmp_path / "run")
    train(config, progress=False)
    out = tmp_path / "real.json"
    main(
        [
            "--checkpoint",
            str(tmp_path / "run/last.pt"),
            "--data",
            f"yolo:{split}",
            "--shift",
            "0.25",
            "--json",
            str(out),
        ]
    )
    report = json.loads(out.read_text())
    assert report["frames"] == 3
    # No ranges on real frames: every cone is in no distance band, all in height bands.
    assert all(row["truths"] == 0 for row in report["recall_by_range"].values())
    assert sum(row["truths"] for row in report["recall_by_height"].values()) > 0
