"""Names `vulture` (the dead-code check of `make lint`, configured in pyproject.toml) reports as
unused although something uses them. vulture counts a name as used when it appears in any file
it scans, so each line here is such a use; the comment says who really uses it.

Only false positives belong here: code nothing uses is deleted instead.
"""

# ruff: noqa: B018, F821

# Read by the Python machinery, not by our code.
_.__signature__  # zooctl/cli/batch_opts.py: what Typer reads to build the options
_.__annotations__  # zooctl/cli/batch_opts.py: likewise
_.find_class  # zooctl/embed/state_dict.py: pickle.Unpickler calls it
_.persistent_load  # zooctl/embed/state_dict.py: pickle.Unpickler calls it
_.writeable  # numpy's array flags, set to protect arrays (io/gltf_import.py, video/flow.py)
_.intra_op_num_threads  # zooctl/video/segment.py: onnxruntime.SessionOptions
_.ir_version  # tests/test_video_segment.py: onnx's ModelProto field
_.log_message  # plugins/zooctl-viewer: overrides http.server's request logging

# Dataclass fields read by name (asdict, getattr, JSON), never as attributes.
_.schema_version  # zooctl/fit/config.py FitConfig: saved in every fit's config.json
_.velocity  # zooctl/motion/train.py TrainHistory: a loss term, appended and plotted by getattr
_.rot_velocity  # zooctl/motion/train.py TrainHistory: likewise
_.top1_plan  # zooctl/retrieval/evaluate.py LooResult: to_json, then the benchmark's table
_.top3_plan
_.top1_skeleton
_.top1_plan_answerable
_.skeleton_queries
_.max_file_mb  # zooctl/limits.py ReadLimits: read by key name (`max_read_bytes("max_file_mb")`)
_.max_json_mb
_.max_array_mb

# Interfaces a plugin implements (docs/plugins.md); nothing in zooctl names them at run time.
_.SilhouetteRenderer  # zooctl/render/base.py
_.ArticulationModel  # zooctl/rig/base.py

# Pytest fixtures a test requests only for what they set up (a plugin installed).
_.example_installed  # tests/test_plugins.py
_.with_plugin  # tests/test_registry_lookups.py
_.clip_installed  # tests/test_retrieval_clip.py

# A file-like object's answers to the io protocol (io.RawIOBase asks them).
_.readable  # zooctl/store/videos.py
_.writable
_.seekable

# socketserver calls it when a request handler thread raises.
_.handle_error  # plugins/zooctl-viewer/zooctl_viewer/serve.py

# xatlas.PackOptions settings, read by the C++ library.
_.resolution  # zooctl/fit/uv_atlas.py
_.bilinear
_.texels_per_unit
