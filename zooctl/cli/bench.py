"""`zooctl bench`: timings of the differentiable core (forward + backward, median ms per frame)."""

from __future__ import annotations

import typer

from ._common import APP_OPTS, ArticulationOpt, DeviceOpt, JsonOpt, console, print_json

app = typer.Typer(**APP_OPTS, help="Benchmark renderers and the articulation model.", no_args_is_help=True)
RepeatsOpt = typer.Option(5, "--repeats", help="Timed runs (the median is reported).")


@app.command("render")
def render(
    renderer: str = typer.Option(
        "soft", "--renderer", help="A registered renderer: soft, fast, flow or a plugin's (`zooctl plugins`)."
    ),
    faces: int = typer.Option(2000, "--faces", help="Triangles in the benchmark sphere."),
    size: int = typer.Option(128, "--size", help="Image size in pixels (square)."),
    batch: int = typer.Option(8, "--batch", help="Frames rendered together."),
    device: str = DeviceOpt,
    repeats: int = RepeatsOpt,
    json_out: bool = JsonOpt,
) -> None:
    """Milliseconds per frame of one renderer's forward + backward."""
    from ..render.benchmark import bench_render

    res = bench_render(renderer, faces=faces, size=size, batch=batch, device=device, repeats=repeats)
    if json_out:
        print_json(res)
    else:
        console.print(
            f"{res['renderer']}: {res['ms_per_frame']:.2f} ms/frame (forward+backward; {res['faces']} faces, "
            f"{size}x{size}, batch {batch}, {device}; {res['machine']})"
        )


@app.command("rig")
def rig(
    vertices: int = typer.Option(4000, "--vertices", help="Vertices of the benchmark tube rig."),
    joints: int = typer.Option(50, "--joints", help="Joints in its chain."),
    frames: int = typer.Option(8, "--frames", help="Frames posed together."),
    articulation: str = ArticulationOpt,
    device: str = DeviceOpt,
    repeats: int = RepeatsOpt,
    json_out: bool = JsonOpt,
) -> None:
    """Milliseconds per frame of FK + skinning (casa: stretchable LBS), forward + backward."""
    from ..render.benchmark import bench_rig

    res = bench_rig(vertices, joints, frames, device, repeats, articulation=articulation or "casa")
    if json_out:
        print_json(res)
    else:
        console.print(
            f"{res['benchmark']}: {res['ms_per_frame']:.2f} ms/frame ({res['vertices']} vertices, {joints} joints, {device})"
        )


from . import bench_retrieval  # noqa: E402  (retrieval accuracy)

bench_retrieval.register(app)

from . import bench_motion  # noqa: E402  (motion prior metrics)

bench_motion.register(app)

from . import bench_fit  # noqa: E402  (CASA fit benchmark)

bench_fit.register(app)
