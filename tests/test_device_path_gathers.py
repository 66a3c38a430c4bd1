"""The path CUDA runs gathers through `index_select`, whose backward adds atomically there.

Advanced indexing (``x[idx]``) backpropagates through a sort of the indices and then sums each run
of equal indices serially. The rasteriser reads face 0 for every background pixel, so one run
held most of an image: on an H200 that backward took 94 % of a stage-2 step's device time
(BENCHMARKS.md, "One NVIDIA H200"). These tests build the device path's graph on the CPU (the C++
kernels off) and fail if a gather of the fit's step goes back to indexing.
"""

import torch

from zooctl.render import _kernels
from zooctl.render.camera import look_at
from zooctl.render.raster import RasterFlow, interpolate, rasterize
from zooctl.render.soft import SoftSilhouette
from zooctl.retrieval.train_data import unweld
from zooctl.rig.model import ArticulatedModel
from zooctl.rig.synthetic import tube_asset


def _backward_nodes(out: torch.Tensor) -> set[str]:
    seen, stack, names = set(), [out.grad_fn], set()
    while stack:
        node = stack.pop()
        if node is None or node in seen:
            continue
        seen.add(node)
        names.add(type(node).__name__)
        stack.extend(n for n, _ in node.next_functions)
    return names


def _tube_model() -> ArticulatedModel:
    # unwelded: every face its own corners, so the surface has seam copies posed once a group
    return ArticulatedModel(unweld(tube_asset(bones=3, rings_per_bone=3)), share_seams=True, girth=True)


def test_the_renderers_device_path_has_no_indexing_backward():
    model = _tube_model()
    q = model.rest_rotation.detach()[None].repeat(2, 1, 1).requires_grad_()
    verts = model(q).vertices
    faces = model.faces
    cam = look_at([0.5, 0.4, 4.0], [1.5, 0.0, 0.0], 32, 40).expand(2)
    with _kernels.disabled():
        frags = rasterize(verts, faces, cam)
        colour = interpolate(verts, faces, frags)
        flow = RasterFlow()(verts, faces, cam, verts.detach() + 0.01)["flow"]
        soft = SoftSilhouette(image_size=(32, 40))(verts, faces, cam)
    assert frags.mask.any() and not frags.mask.all()  # background pixels: the case that was slow
    for out in (colour.sum() + frags.depth.sum(), flow.sum(), soft.sum()):
        names = _backward_nodes(out)
        assert "IndexSelectBackward0" in names
        assert "IndexBackward0" not in names, names


def test_the_models_pose_has_no_indexing_backward():
    model = _tube_model()
    assert model.surface_index is not None and model.log_bone_girth is not None
    q = model.rest_rotation.detach()[None].repeat(3, 1, 1).requires_grad_()
    pose = model(q)
    loss = pose.vertices.sum() + model.symmetry_loss(sample=20) + model.bone_length_loss()
    names = _backward_nodes(loss)
    assert "IndexBackward0" not in names, names
    loss.backward()
    assert all(p.grad is not None for p in (q, model.log_bone_girth))
