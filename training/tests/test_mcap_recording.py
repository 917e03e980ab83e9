"""A `conesight record` recording read with the public Python `mcap` + protobuf readers only.

The camera service of `conesight run` publishes frames, camera info and (the renderer's) boxes
on loopback; `conesight record` records them; then every message of the file is decoded with
the protobuf schema the file itself carries (`mcap_protobuf`), with no conesight code.
Skipped when the `conesight` binary is not built.
"""

import subprocess
from pathlib import Path

import pytest
from conesight_process import find_binary, free_port

mcap_reader = pytest.importorskip("mcap.reader")
mcap_protobuf = pytest.importorskip("mcap_protobuf.decoder")

EXPECTED_SCHEMAS = {
    "conesight.v1.ImageFrame",
    "conesight.v1.CameraInfo",
    "conesight.v1.Detections",
}


def test_every_message_decodes_with_the_schema_the_file_carries(tmp_path: Path) -> None:
    binary = find_binary()
    if binary is None:
        pytest.skip("target/*/conesight not built (cargo build -p conesight-cli)")
    if (
        "record"
        not in subprocess.run([binary, "--help"], capture_output=True, text=True, check=True).stdout
    ):
        pytest.skip("this conesight binary has no `record` subcommand (rebuild it)")
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    namespace = f"pytest{free_port()}"
    out = tmp_path / "run.mcap"
    recorder = subprocess.Popen(
        [
            *(binary, "record", "--namespace", namespace, "--zenoh-listen", endpoint),
            *("--out", str(out), "--duration-s", "8", "--record-frames", "jpeg"),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        subprocess.run(
            [
                *(binary, "run", "--services", "camera", "--boxes", "truth"),
                *("--namespace", namespace, "--zenoh-connect", endpoint),
                *("--zenoh-listen", "tcp/127.0.0.1:0", "--frames", "20", "--rate-hz", "10"),
                *("--preload", "2", "--out", str(tmp_path / "run")),
            ],
            capture_output=True,
            text=True,
            timeout=120,
            check=False,
        )
        stdout, stderr = recorder.communicate(timeout=60)
    finally:
        recorder.kill()
    assert recorder.returncode == 0, stderr
    decoder = mcap_protobuf.DecoderFactory()
    counts: dict[str, int] = {}
    with out.open("rb") as stream:
        reader = mcap_reader.make_reader(stream, decoder_factories=[decoder])
        for schema, channel, _message, decoded in reader.iter_decoded_messages():
            assert schema is not None and schema.encoding == "protobuf"
            assert channel.topic.startswith(f"conesight/{namespace}/car/front/")
            assert decoded.header.camera_id == "front"
            counts[schema.name] = counts.get(schema.name, 0) + 1
            if schema.name == "conesight.v1.ImageFrame":
                assert decoded.width_px > 0 and len(decoded.data) > 0
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
    assert set(counts) >= EXPECTED_SCHEMAS, counts
    assert counts["conesight.v1.ImageFrame"] >= 10, (counts, stdout)
    assert metadata["conesight"]["namespace"] == namespace
    assert any(name.startswith("calibration/") for name in metadata), metadata
