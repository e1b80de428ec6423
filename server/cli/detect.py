"""`skyring detect`: one MAV's camera and person detector, beside its agent (docs/detection.md).

Reads frames from a V4L2 device, a network stream, a GStreamer pipeline or a video file, finds the person
(head and feet pixels with confidences) and sends each detection, stamped with its capture time, to the
MAV's agent; reports the camera's health with a thumbnail about once a second. Bad options end the command
with status 2 and one line naming the option; a camera that fails at run time is reported and retried.
"""

from __future__ import annotations

import math
import signal
import sys
from pathlib import Path
from typing import Annotated, NoReturn

import typer

BACKENDS = ("default", "onnx")


def _fail(message: str, code: int = 2) -> NoReturn:
    typer.echo(f"Error: {message}", err=True)
    raise typer.Exit(code=code)


def detect(
    vehicle_id: Annotated[int, typer.Option("--id", help="the MAV this camera is on (its agent's id)")] = 0,
    camera: Annotated[
        str, typer.Option(help="0 or /dev/videoN, rtsp://..., a GStreamer pipeline, or a file")
    ] = "",
    calibration: Annotated[
        Path | None, typer.Option(help="OpenCV YAML calibration (default: the simulated camera)")
    ] = None,
    backend: Annotated[str, typer.Option(help="default (HOG + MediaPipe pose) or onnx")] = "default",
    onnx_model: Annotated[Path | None, typer.Option(help="the ONNX pose model for --backend onnx")] = None,
    min_person_px: Annotated[float, typer.Option(help="smallest person (pixels) a search looks for")] = 64.0,
    out: Annotated[
        str, typer.Option(help="also write detections and reports as JSON Lines here ('-': stdout)")
    ] = "",
    preview: Annotated[
        Path | None, typer.Option(help="write overlaid frames: a folder or a .avi file")
    ] = None,
    preview_port: Annotated[
        int, typer.Option(help="stream overlaid frames as MJPEG on this port (0: off)")
    ] = 0,
    preview_host: Annotated[str, typer.Option(help="address the MJPEG preview listens on")] = "127.0.0.1",
    max_fps: Annotated[
        float, typer.Option(help="process at most this many frames per second (0: no limit)")
    ] = 0.0,
    loop: Annotated[bool, typer.Option(help="restart a video file at its end")] = False,
    realtime: Annotated[bool, typer.Option(help="play a video file at its own frame rate")] = True,
    frames: Annotated[int, typer.Option(help="stop after this many frames (0: no limit)")] = 0,
    duration: Annotated[float, typer.Option(help="stop after this many seconds (0: no limit)")] = 0.0,
    capture_latency_s: Annotated[
        float, typer.Option(help="camera delay before a frame is grabbed (s)")
    ] = 0.0,
    write_calibration: Annotated[
        Path | None, typer.Option(help="write the calibration in use (a template to edit) and exit")
    ] = None,
    zenoh: Annotated[bool, typer.Option(help="publish to the MAV's agent and the station over Zenoh")] = True,
    team: Annotated[
        str, typer.Option(help="team name (the Zenoh key prefix skyring/<team>/...)")
    ] = "skyring",
    connect: Annotated[
        list[str] | None, typer.Option(help="Zenoh endpoint to connect to (repeatable)")
    ] = None,
    listen: Annotated[list[str] | None, typer.Option(help="Zenoh endpoint to listen on (repeatable)")] = None,
    zenoh_config: Annotated[
        Path | None, typer.Option(help="Zenoh JSON5 config (TLS/mTLS, access control)")
    ] = None,
    multicast: Annotated[bool, typer.Option(help="find peers by multicast scouting")] = True,
) -> None:
    """Detect the person in one MAV's camera and send head/feet detections to its agent."""
    from vehicles.detect.calibration import Calibration, CalibrationError

    try:
        calib = Calibration.load(calibration) if calibration is not None else Calibration.from_camera_params()
    except CalibrationError as exc:
        _fail(f"invalid value for --calibration: {exc}")
    if write_calibration is not None:
        calib.save(write_calibration)
        typer.echo(f"wrote {write_calibration}")
        return
    if vehicle_id < 1:
        _fail("invalid value for --id: give the MAV's id (1 or more)")
    if not camera:
        _fail("missing --camera: a device (0, /dev/video0), a URL (rtsp://...), a pipeline or a video file")
    if backend not in BACKENDS:
        _fail(f"invalid value for --backend: choose one of {', '.join(BACKENDS)}, got {backend!r}")
    if backend == "onnx" and (onnx_model is None or not onnx_model.is_file()):
        _fail("invalid value for --onnx-model: --backend onnx needs an existing .onnx file")
    for name, value in (("--min-person-px", min_person_px), ("--max-fps", max_fps), ("--duration", duration)):
        if not (math.isfinite(value) and value >= 0):
            _fail(f"invalid value for {name}: must be a finite number >= 0, got {value}")
    if not (math.isfinite(capture_latency_s) and 0 <= capture_latency_s < 5):
        _fail(f"invalid value for --capture-latency-s: must be in [0, 5), got {capture_latency_s}")

    from vehicles.detect.camera_source import CameraReader, ReaderParams, parse_source
    from vehicles.detect.pipeline import DetectionPipeline
    from vehicles.detect.preview import MjpegServer, PreviewWriter
    from vehicles.detect.runner import DetectionSink, DetectorRunner, JsonlSink, RunnerParams

    try:
        spec = parse_source(camera)
    except ValueError as exc:
        _fail(f"invalid value for --camera: {exc}")
    try:
        detector = _make_backend(backend, onnx_model, min_person_px)
    except Exception as exc:  # a missing pose environment or a bad model file: say so and stop
        _fail(f"cannot start the {backend} back-end: {exc}", code=1)
    reader = CameraReader(
        spec,
        ReaderParams(
            realtime=realtime,
            loop=loop,
            capture_latency_s=capture_latency_s,
            expected_size_px=(calib.width_px, calib.height_px) if calibration is not None else None,
        ),
    )
    sinks: list[DetectionSink] = []
    if zenoh:
        from server.cli.agent import net_config
        from vehicles.net.camera_publisher import ZenohCameraSink

        try:
            config = net_config(
                team=team, connect=connect, listen=listen, zenoh_config=zenoh_config, multicast=multicast
            )
        except typer.BadParameter as exc:
            _fail(f"invalid Zenoh option: {exc.message}")
        sinks.append(ZenohCameraSink(config, vehicle_id=vehicle_id))
    if out:
        sinks.append(JsonlSink(sys.stdout) if out == "-" else JsonlSink.to_path(out))
    writer = PreviewWriter(preview) if preview is not None else None
    mjpeg = MjpegServer(host=preview_host, port=preview_port) if preview_port > 0 else None
    runner = DetectorRunner(
        vehicle_id=vehicle_id,
        reader=reader,
        pipeline=DetectionPipeline(detector),
        sinks=sinks,
        preview=writer,
        mjpeg=mjpeg,
        params=RunnerParams(max_fps=max_fps),
        log=lambda msg: typer.echo(msg, err=True),
    )
    signal.signal(signal.SIGTERM, lambda *_: runner.stop())
    where = f", Zenoh team {team}" if zenoh else ""
    typer.echo(f"skyring detect: MAV {vehicle_id}, {spec.label}, back-end {detector.name}{where}", err=True)
    if mjpeg is not None:
        typer.echo(f"preview: http://{preview_host}:{mjpeg.port}/", err=True)
    reader.start()
    try:
        summary = runner.run(max_frames=frames or None, duration_s=duration or None)
    except KeyboardInterrupt:
        summary = None
    finally:
        reader.stop()
        detector.close()
        for sink in sinks:
            sink.close()
        if writer is not None:
            writer.close()
        if mjpeg is not None:
            mjpeg.close()
    if summary is not None:
        state = summary.camera.state if summary.camera is not None else "?"
        typer.echo(
            f"frames {summary.frames}, detections {summary.detections}, searches {summary.searches}, "
            f"detector errors {summary.detector_errors}, camera {state}",
            err=True,
        )


def _make_backend(name: str, onnx_model: Path | None, min_person_px: float):
    from vehicles.detect.hog import HogParams

    if name == "onnx":
        from vehicles.detect.onnx import OnnxPoseDetector

        assert onnx_model is not None
        return OnnxPoseDetector(onnx_model)
    from vehicles.detect.backends import HogPoseDetector

    det = HogPoseDetector(hog=HogParams(min_person_px=min_person_px))
    det.pose.start()
    return det
