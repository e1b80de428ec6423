"""The ONNX plug-in point, with a real ONNX model run by onnxruntime.

The model is built here with onnx.helper: it ignores its image (adds 0 times its mean) and returns fixed
candidates in the YOLO-pose layout. That checks what the plug-in owns (loading, the input contract,
letterboxing and crops, decoding, score filtering, non-maximum suppression, mapping back to image pixels,
head and feet from COCO keypoints), not what a trained model's weights would find.
"""

from __future__ import annotations

import numpy as np
import pytest

from vehicles.detect.onnx import ANKLE_HEIGHT, OnnxPoseDetector
from vehicles.detect.pose import CROWN_ABOVE_EARS

S = 64


def _person_row(cx: float, top: float, bottom: float, score: float) -> np.ndarray:
    """One candidate: an upright person from top (ears) to bottom (ankles) at x = cx, input pixels."""
    h = bottom - top
    kps = np.zeros((17, 3), np.float32)
    kps[:, 0] = cx
    kps[:, 2] = 0.9
    kps[:5, 1] = top  # nose, eyes, ears
    kps[5:7, 1] = top + 0.15 * h  # shoulders
    kps[11:13, 1] = top + 0.5 * h  # hips
    kps[13:15, 1] = top + 0.75 * h
    kps[15:17, 1] = bottom  # ankles
    return np.concatenate([[cx, (top + bottom) / 2, 0.4 * h, 1.2 * h, score], kps.ravel()]).astype(np.float32)


@pytest.fixture
def model(tmp_path):
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    rows = np.stack(
        [
            _person_row(32.0, 20.0, 44.0, 0.9),
            _person_row(33.0, 21.0, 44.0, 0.6),  # the same person, weaker: suppressed
            _person_row(10.0, 20.0, 30.0, 0.1),  # below the score threshold
        ]
    ).T[None]  # (1, 56, 3)
    const = numpy_helper.from_array(rows, name="cands")
    graph = helper.make_graph(
        [
            helper.make_node("ReduceMean", ["images"], ["mean"], keepdims=0),
            helper.make_node("Mul", ["mean", "zero"], ["nothing"]),
            helper.make_node("Add", ["cands", "nothing"], ["output0"]),
        ],
        "fixed-pose",
        [helper.make_tensor_value_info("images", TensorProto.FLOAT, [1, 3, S, S])],
        [helper.make_tensor_value_info("output0", TensorProto.FLOAT, [1, 56, 3])],
        initializer=[const, numpy_helper.from_array(np.zeros((), np.float32), name="zero")],
    )
    m = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)])
    m.ir_version = 8
    path = tmp_path / "pose.onnx"
    onnx.save(m, str(path))
    return path


def test_find_maps_keypoints_back_through_the_letterbox(model):
    det = OnnxPoseDetector(model)
    image = np.zeros((64, 128, 3), np.uint8)  # letterboxed: scale 0.5, 16 px of padding above
    people = det.find(image)
    assert len(people) == 1  # one suppressed by NMS, one below the score
    p = people[0]
    ears = np.array([32.0 / 0.5, (20.0 - 16) / 0.5])
    ankles = np.array([32.0 / 0.5, (44.0 - 16) / 0.5])
    span = ankles[1] - ears[1]
    np.testing.assert_allclose(p.head_px, ears - [0, CROWN_ABOVE_EARS * span], atol=1e-3)
    np.testing.assert_allclose(p.feet_px, ankles + [0, ANKLE_HEIGHT * span], atol=1e-3)
    assert p.head_conf == pytest.approx(0.9) and p.score == pytest.approx(0.9)


def test_refine_maps_keypoints_back_from_the_crop(model):
    det = OnnxPoseDetector(model, crop_side=2.0)
    image = np.zeros((200, 300, 3), np.uint8)
    box = np.array([140.0, 60.0, 160.0, 92.0])  # 32 px tall: the crop is 64 px, 1:1, centred at (150, 76)
    p = det.refine(image, box)
    assert p is not None
    # crop pixel c maps to image pixel c - 32 + centre
    np.testing.assert_allclose(p.feet_px[0], 32.0 - 32.0 + 150.0, atol=1e-3)
    span = 44.0 - 20.0
    np.testing.assert_allclose(p.feet_px[1], 44.0 + ANKLE_HEIGHT * span - 32.0 + 76.0, atol=1e-3)


def test_a_model_with_the_wrong_input_is_refused(tmp_path):
    import onnx
    from onnx import TensorProto, helper

    graph = helper.make_graph(
        [helper.make_node("Identity", ["x"], ["y"])],
        "wrong",
        [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, 4])],
        [helper.make_tensor_value_info("y", TensorProto.FLOAT, [1, 4])],
    )
    m = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)])
    m.ir_version = 8
    onnx.save(m, str(tmp_path / "wrong.onnx"))
    with pytest.raises(ValueError, match=r"\(1, 3, S, S\) input"):
        OnnxPoseDetector(tmp_path / "wrong.onnx")
