"""Hook specifications: the whole contract between zooctl and its plugins.

A plugin is a module (or object) that implements some of these hooks, decorated with
``zooctl.hookimpl``, and is advertised by a distribution through the ``zooctl`` entry-point group:

.. code-block:: toml

    [project.entry-points.zooctl]
    toy = "zooctl_example.plugin"

Every hook except `register_commands` is a *register-callback* hook: zooctl calls it once with a
``register`` callable, and the plugin calls ``register(spec)`` for each component it provides
(specs are in `zooctl.components`). Plugins should import heavy dependencies inside their
factories, not at module import time, so that ``zooctl --help`` stays fast.

zooctl's own built-in components are registered through exactly the same entry points.
"""

from __future__ import annotations

import pluggy

hookspec = pluggy.HookspecMarker("zooctl")


@hookspec
def register_importers(register):
    """Register asset importers, chosen by file suffix.

    :param register: call ``register(ImporterSpec(name, suffixes, load))`` once per importer.

    ``load(path, name)`` must return a validated `zooctl.asset.RiggedAsset` named ``name`` and raise
    `zooctl.errors.InputError` (one line saying what is wrong with the file) for bad input. When two
    importers claim the same suffix, the first registered wins and the conflict is reported by
    ``zooctl plugins``.
    """


@hookspec
def register_exporters(register):
    """Register asset exporters, chosen by ``--format``.

    :param register: call ``register(ExporterSpec(name, formats, save))`` once per exporter.

    ``save(asset, path, clips=None, **options)`` writes the asset (and the named clips, or all) to
    ``path``. It must write atomically: a temporary beside ``path``, then ``os.replace``. The
    spec's ``suffixes`` (one per format) let every export command resolve paths
    (`zooctl.io.asset_export.export_asset`).
    """


@hookspec
def register_embedders(register):
    """Register image embedders used for video-to-template retrieval.

    :param register: call ``register(ComponentSpec("embedder", name, factory))``.

    ``factory(device="cpu", **options)`` returns an object with ``dim: int`` and
    ``embed_batch(images) -> (N, dim) float32`` where ``images`` is an (N, H, W, 3) uint8 RGB array;
    embeddings are compared by cosine distance. An ``identity: str`` attribute that changes with
    the weights (e.g. ``zooctl.embed.base.file_digest`` of the weights file) lets a search refuse
    bank views embedded by another version of the embedder; without it, name and ``dim`` stand in.
    """


@hookspec
def register_renderers(register):
    """Register renderers (differentiable silhouettes, flow, shaded previews).

    :param register: call ``register(ComponentSpec("renderer", name, factory))``.

    ``factory(image_size, device="cpu", **options)`` returns a ``torch.nn.Module``-like object whose
    call maps batched posed vertices (B, V, 3), faces (F, 3) and a `zooctl.render.camera` camera
    batch to the images it renders: (B, H, W) coverage for a silhouette renderer (what
    ``zooctl fit --renderer NAME`` uses), a dict with ``flow`` for a flow renderer. The interfaces
    are in `zooctl.render.base`.
    """


@hookspec
def register_articulation_models(register):
    """Register articulation models (how bones move the mesh).

    :param register: call ``register(ComponentSpec("articulation_model", name, factory))``.

    ``factory(asset, device="cpu", **options)`` returns a ``torch.nn.Module`` that maps per-frame
    joint rotations and a root transform to posed vertices (T, V, 3) and joint positions (T, J, 3),
    and owns its learnable shape parameters (bone scales, skinning, offsets); ``zooctl fit
    --articulation NAME`` uses it. The full interface is in `zooctl.rig.base`.
    """


@hookspec
def register_motion_priors(register):
    """Register generative motion priors.

    :param register: call ``register(ComponentSpec("motion_prior", name, factory))``.

    ``factory(path=None, device="cpu", **options)`` returns an object that can ``fit`` a motion
    dataset, ``save(path)``, and ``sample(asset, n, frames, seed) -> (n, frames, J, 4)`` local
    rotations for any skeleton. Optionally ``sequence_prior(asset, video_fps)`` returns an object
    whose ``loss(rotations (T, J, 4), frames (B,)) -> scalar tensor`` scores a fit's local rotations
    around the given video frames, differentiably (lower: more like the motion it learned); the
    fit's pose prior ``motion`` uses it.
    """


@hookspec
def register_segmenters(register):
    """Register video segmenters that produce the animal's masks.

    :param register: call ``register(ComponentSpec("segmenter", name, factory))``.

    ``factory(**options)`` returns an object with
    ``segment(frames, box=None, progress=None) -> (T, H, W) bool``; ``frames`` is (T, H, W, 3) uint8.
    A segmenter that sets the attribute ``uses_flow = True`` is also passed ``flow=`` (the forward
    flow the video store computes anyway: a `zooctl.video.flow.VideoFlow`), so it is not computed twice.
    """


@hookspec
def register_flow_estimators(register):
    """Register optical-flow estimators.

    :param register: call ``register(ComponentSpec("flow_estimator", name, factory))``.

    ``factory(**options)`` returns an object with ``flow(frame_a, frame_b) -> (H, W, 2) float32``,
    the pixel displacement from a to b. One that sets ``thread_safe = True`` may be called from
    several threads at once: `video add` then computes the frame pairs on all cores.
    """


@hookspec
def register_executors(register):
    """Register executors: where the tasks of a batch run (``--executor NAME``).

    :param register: call ``register(ComponentSpec("executor", name, factory))``.

    Built in: ``local`` (this process, or ``--jobs N`` processes); the first-party distribution
    ``plugins/zooctl-ray`` adds ``ray``. Batch commands (``zooctl fit VIDEO...``, ``bank add
    FILES... --executor``, ``bank reindex --executor``, ``bench run --executor``) build one with
    ``factory(jobs=None, address=None, cpus_per_task=1.0, gpus_per_task=0.0, retries=2, env={})``
    (`zooctl.executors.base.ExecutorOptions`; a factory raises `zooctl.errors.UsageError` for an
    option it cannot honour, e.g. ``local`` and ``--address``). The object has:

    - ``name: str`` and ``slots: int`` (how many tasks run at once);
    - ``map(fn, items, on_stage=None)``: run ``fn(item, report)`` on every item and yield one
      `zooctl.executors.base.TaskOutcome` per item (its index, value or error, attempts) as each
      finishes, in any order. Run each task through `zooctl.executors.base.call_task`, which
      turns a `zooctl.errors.ZooctlError` into the item's error (bad input: never retried) and
      applies ``env`` and the thread count in the worker. Any other exception, or a worker or
      node that dies, is retried at most ``retries`` more times, then reported as the item's
      error. ``report(stage)`` in the task must reach ``on_stage(index, stage)`` on the driver
      (best effort). Closing the iterator (Ctrl-C) cancels the tasks still running;
    - ``close()``: release what the executor started (pools, a Ray instance it started).

    ``fn`` is a module-level function and ``items`` are picklable; an executor must never write
    the store: `zooctl.pipelines.batch` commits each returned value once, on the driver.
    """


@hookspec
def register_commands(cli):
    """Add commands or command groups to the ``zooctl`` CLI.

    :param cli: the root ``typer.Typer`` application. Use ``@cli.command()`` or
        ``cli.add_typer(group, name=...)``. Commands should stay thin and raise
        `zooctl.errors.ZooctlError` subclasses for anything the user got wrong.
    """
