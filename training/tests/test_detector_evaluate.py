"""The evaluation CLI on a renderer-like folder (our JSON + calibration) and on unlabelled
frames: metrics JSON, annotated PNGs, counts per frame."""

import json

import cv2
import numpy as np

from conesight_train.detector.band import BandParams
from conesight_train.detector.config import TrainConfig
from conesight_train.detector.data import RendererFrames, ToyFrames
from conesight_train.detector.evaluate import main
from conesight_train.detector.model import DetectorParams
from conesight_train.detector.train import train

BAND = BandParams(band_top_px=32, input_width_px=128, input_height_px=64, factor=2)
TINY = DetectorParams(
    stem_channels=8, stage_channels=(8, 16, 16, 16), stage_blocks=(1, 1, 1, 1), neck_channels=8
)


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
        # Horizon at row 40 (cy 40, level camera) -> band top 0.
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
    assert frame.band_top_px == 0 and len(frame.boxes_px) > 0
    config = TrainConfig(
        train=str(data),
        val=str(data),
        out=str(tmp_path / "run"),
        steps=2,
        batch_size=2,
        val_every=2,
        warmup_steps=1,
        workers=0,
        band=BAND,
        model=TINY,
    )
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
