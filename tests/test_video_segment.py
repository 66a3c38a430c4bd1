"""Segmenters: user masks (validated), the classical GrabCut tracker, and an ONNX model built here."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import VIDEOS_DIR, needs_shared_videos
from PIL import Image
from video_helpers import iou, moving_object_video

from zooctl.errors import InputError, UsageError
from zooctl.io.video import write_mp4
from zooctl.plugins import get_registry
from zooctl.video import cues


@pytest.fixture(scope="module")
def synthetic():
    return moving_object_video(t=8, h=96, w=128)


def save_masks(folder, masks, mode="L"):
    folder.mkdir(parents=True, exist_ok=True)
    for i, m in enumerate(masks):
        img = Image.fromarray(m.astype(np.uint8) * (255 if mode == "L" else 1))
        if mode == "P":
            img = img.convert("P")
        img.save(folder / f"{i:05d}.png")
    return folder


def masks_seg(**kw):
    return get_registry().get("segmenter", "masks").create(**kw)


def test_mask_folder_roundtrip_and_palette_pngs(tmp_path, synthetic):
    frames, masks = synthetic
    for mode in ("L", "P"):
        got = masks_seg(path=save_masks(tmp_path / mode, masks, mode)).segment(frames)
        assert got.dtype == bool and np.array_equal(got, masks)


def test_masks_at_original_size_are_resized_and_subsampled(tmp_path, synthetic):
    frames, masks = synthetic
    big = np.repeat(np.repeat(masks, 2, 1), 2, 2)  # the "original" video was twice the size
    folder = save_masks(tmp_path / "m", big)
    got = masks_seg(path=folder, original_size=(256, 192)).segment(frames)
    assert iou(got, masks) > 0.98
    # the stored video kept every other source frame: masks are picked by source index
    got = masks_seg(path=folder, source_indices=[0, 2, 4, 6], original_size=(256, 192)).segment(frames[::2])
    assert iou(got, masks[::2]) > 0.98


def test_mask_count_and_size_mismatches_are_errors(tmp_path, synthetic):
    frames, masks = synthetic
    folder = save_masks(tmp_path / "short", masks[:5])
    with pytest.raises(InputError, match="5 masks .* 8 frames"):
        masks_seg(path=folder).segment(frames)
    folder = save_masks(tmp_path / "small", masks[:, ::2, ::2])
    with pytest.raises(InputError, match="is 64x48, the frames are 128x96"):
        masks_seg(path=folder).segment(frames)
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(InputError, match="no mask images"):
        masks_seg(path=empty).segment(frames)


def test_mask_video(tmp_path, synthetic):
    frames, masks = synthetic
    video = write_mp4(
        tmp_path / "masks.mp4", np.repeat(masks[..., None], 3, -1).astype(np.uint8) * 255, fps=30, quality=10
    )
    got = masks_seg(path=video).segment(frames)
    assert iou(got, masks) > 0.95


def test_grabcut_tracks_a_moving_object(synthetic):
    frames, masks = synthetic
    seg = get_registry().get("segmenter", "grabcut").create()
    got = seg.segment(frames, box=cues.box_of(masks[0]))
    assert got.shape == masks.shape
    ious = [iou(g, m) for g, m in zip(got, masks)]
    assert min(ious) > 0.85, ious
    x, y, w, h = cues.box_of(masks[0])
    sloppy = (x + 5, y + 5, w, h)  # cuts off the left and top of the object: the margin option helps
    loose = get_registry().get("segmenter", "grabcut").create(box_margin=0.1).segment(frames, box=sloppy)
    assert min(iou(g, m) for g, m in zip(loose, masks)) > 0.85
    auto = seg.segment(frames)  # no box: the object that moves unlike the camera
    assert iou(auto[0], masks[0]) > 0.8


def test_grabcut_bad_box_and_static_scene(synthetic):
    frames, _ = synthetic
    seg = get_registry().get("segmenter", "grabcut").create()
    with pytest.raises(UsageError, match="does not cover"):
        seg.segment(frames, box=(500, 500, 10, 10))
    # nothing moves and nothing looks like an animal: no masks (video add reports it), no failure
    still = np.full((3, *frames.shape[1:]), 128, np.uint8)
    assert not seg.segment(still).any() and set(seg.report["seeding"]) == {"empty"}


@needs_shared_videos
def test_grabcut_on_real_davis_frames():
    from zooctl.video.decode import decode
    from zooctl.video.segment import MaskSegmenter

    dv = decode(VIDEOS_DIR / "cows", max_frames=6, max_size=320)
    gt = MaskSegmenter(VIDEOS_DIR / "cows", dv.source_indices, dv.original_size).segment(dv.frames)
    box = cues.box_of(gt[0])
    seg = get_registry().get("segmenter", "grabcut").create()
    got = seg.segment(dv.frames, box=box)  # the box chooses the cow, the localiser seeds it
    assert seg.report["box_use"] == "chose the animal"
    assert np.mean([iou(g, m) for g, m in zip(got, gt)]) > 0.65
    seg = get_registry().get("segmenter", "grabcut").create(localise=False)
    got = seg.segment(dv.frames, box=box)  # the box's own pixels seed frame 0
    assert seg.report["box_use"] == "seeded"
    assert np.mean([iou(g, m) for g, m in zip(got, gt)]) > 0.7
    # no box: the localiser's seed starts GrabCut with the class map's region, so the cow's white
    # belly and head (the ground's colours, barely moving) are in it (0.69; 0.48 without)
    j = {}
    for from_map in (True, False):
        got = get_registry().get("segmenter", "grabcut").create(seed_from_map=from_map).segment(dv.frames)
        j[from_map] = np.mean([iou(g, m) for g, m in zip(got, gt)])
    assert j[True] > 0.6 and j[True] > j[False] + 0.1, j


def _needs_onnx() -> None:
    pytest.importorskip("onnxruntime", reason="onnxruntime is not installed (optional dependency)")
    pytest.importorskip("onnx", reason="the onnx package is needed to build the test model")


def _save_onnx(graph, path):
    """``graph`` as an opset-13, IR-8 model file at ``path``."""
    import onnx
    from onnx import helper

    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)])
    model.ir_version = 8
    onnx.save(model, str(path))
    return path


def _red_detector_onnx(path):
    """A 1x1 conv scoring "red minus the rest", then a sigmoid: a model built by the test itself."""
    from onnx import TensorProto, helper, numpy_helper

    w = numpy_helper.from_array(np.array([[[[24.0]], [[-12.0]], [[-12.0]]]], np.float32), "w")
    b = numpy_helper.from_array(np.array([-7.5], np.float32), "b")
    graph = helper.make_graph(
        [helper.make_node("Conv", ["x", "w", "b"], ["logit"]), helper.make_node("Sigmoid", ["logit"], ["p"])],
        "red",
        [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, 3, 64, 64])],
        [helper.make_tensor_value_info("p", TensorProto.FLOAT, [1, 1, 64, 64])],
        initializer=[w, b],
    )
    return _save_onnx(graph, path)


def test_onnx_segmenter_runs_a_local_model(tmp_path, synthetic):
    _needs_onnx()
    frames, masks = synthetic
    model = _red_detector_onnx(tmp_path / "red.onnx")
    seg = (
        get_registry()
        .get("segmenter", "onnx")
        .create(model=model, mean=(0, 0, 0), std=(1, 1, 1), normalize=False)
    )
    assert seg.size == (64, 64)  # the model's static input size wins over input_size
    got = seg.segment(frames)
    assert np.mean([iou(g, m) for g, m in zip(got, masks)]) > 0.85
    with pytest.raises(InputError, match="does not exist"):
        get_registry().get("segmenter", "onnx").create(model=tmp_path / "none.onnx")
    (tmp_path / "bad.onnx").write_bytes(b"not a model")
    with pytest.raises(InputError, match="not a loadable ONNX model"):
        get_registry().get("segmenter", "onnx").create(model=tmp_path / "bad.onnx")
    with pytest.raises(UsageError, match="needs a model"):
        get_registry().get("segmenter", "onnx").create()


def _box_prompted_onnx(path, extra_input: str | None = None):
    """A promptable model built here: image (1, 3, 64, 64), box (1, 4) x0 y0 x1 y1 and one point
    (1, 1, 2) with its label (1, 1), in input pixels; mask logits (1, 1, 64, 64) positive inside
    the box: min(x - x0, x1 - x, y - y0, y1 - y). The image and the point are used only to show
    they arrive (times zero)."""
    from onnx import TensorProto, helper, numpy_helper

    yy, xx = np.mgrid[0:64, 0:64].astype(np.float32) + 0.5
    init = [
        numpy_helper.from_array(xx[None, None], "X"),
        numpy_helper.from_array(yy[None, None], "Y"),
        numpy_helper.from_array(np.zeros((1,), np.float32), "zero"),
    ] + [numpy_helper.from_array(np.array([k], np.int64), f"i{k}") for k in range(4)]
    nodes = [helper.make_node("Gather", ["box", f"i{k}"], [f"b{k}"], axis=1) for k in range(4)]
    nodes += [
        helper.make_node("Sub", ["X", "b0"], ["l"]),
        helper.make_node("Sub", ["b2", "X"], ["r"]),
        helper.make_node("Sub", ["Y", "b1"], ["t"]),
        helper.make_node("Sub", ["b3", "Y"], ["d"]),
        helper.make_node("Min", ["l", "r", "t", "d"], ["inside"]),
        helper.make_node("ReduceMean", ["image"], ["im"], keepdims=1),
        helper.make_node("ReduceMean", ["point_coords"], ["pt"], keepdims=0),
        helper.make_node("ReduceMean", ["point_labels"], ["lb"], keepdims=0),
        helper.make_node("Add", ["im", "pt"], ["s1"]),
        helper.make_node("Add", ["s1", "lb"], ["s2"]),
        helper.make_node("Mul", ["s2", "zero"], ["nothing"]),
        helper.make_node("Add", ["inside", "nothing"], ["logits"]),
    ]
    inputs = [
        helper.make_tensor_value_info("image", TensorProto.FLOAT, [1, 3, 64, 64]),
        helper.make_tensor_value_info("box", TensorProto.FLOAT, [1, 4]),
        helper.make_tensor_value_info("point_coords", TensorProto.FLOAT, [1, 1, 2]),
        helper.make_tensor_value_info("point_labels", TensorProto.FLOAT, [1, 1]),
    ]
    if extra_input:
        inputs.append(helper.make_tensor_value_info(extra_input, TensorProto.FLOAT, [1]))
    graph = helper.make_graph(
        nodes,
        "prompted",
        inputs,
        [helper.make_tensor_value_info("logits", TensorProto.FLOAT, [1, 1, 64, 64])],
        initializer=init,
    )
    return _save_onnx(graph, path)


def test_onnx_segmenter_feeds_box_and_point_prompts(tmp_path, synthetic):
    _needs_onnx()
    frames = synthetic[0]  # 96 x 128: the 64 x 64 model sees x scaled by 1/2, y by 2/3
    create = get_registry().get("segmenter", "onnx").create
    seg = create(model=_box_prompted_onnx(tmp_path / "p.onnx"), normalize=False, prompt_margin=0.0)
    assert seg.prompts == {"box", "point_coords", "point_labels"}
    box = (32, 24, 48, 36)  # x, y, w, h in frame pixels
    got = seg.segment(frames[:4], box=box, box_frame=2)
    want = cues.box_mask(frames.shape[1:3], box)
    assert iou(got[2], want) > 0.9  # the prompt arrived in the model's pixels and came back
    assert all(iou(got[i], want) > 0.9 for i in (0, 1, 3))  # each neighbour's mask prompts the next
    whole = seg.segment(frames[:2])  # no box: the whole frame is the prompt
    assert whole.mean() > 0.9
    grown = create(model=tmp_path / "p.onnx", normalize=False, prompt_margin=0.25).segment(
        frames[:2], box=box
    )
    assert grown[1].sum() > 1.5 * grown[0].sum()  # the next prompt is the mask's box, grown
    with pytest.raises(InputError, match="has inputs mask_input the onnx segmenter cannot feed"):
        create(model=_box_prompted_onnx(tmp_path / "q.onnx", extra_input="mask_input"))
