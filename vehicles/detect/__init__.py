"""Onboard person detection from a real camera (docs/detection.md).

Camera sources with capture time stamps (`camera_source`), the calibration file (`calibration`), detector
back-ends giving head and feet pixels (`hog`, `pose`, `onnx`, combined by `pipeline`), and the agent-side
conversion of a pixel detection into a world-frame `Detection` (`pose_history`, `localize`). The `skyring
detect` process (server/cli/detect.py) runs the camera side; the agent runs the conversion.

Everything here except `localize`, `pose_history`, `pixels` and `calibration` needs OpenCV; nothing imports
it at module level in the modules the agent uses, so the agent stays importable without a camera stack.
"""
