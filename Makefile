# Every target creates and uses .venv itself, so each works alone from a clean clone.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.zooctl-installed
TEST_STAMP := $(VENV)/.zooctl-test-extras
VIEWER_STAMP := $(VENV)/.zooctl-viewer
# torch first: 2.13.0 (CPU) is on this machine's disk; any other spec may pull a CUDA build.
TORCH_SPEC ?= torch==2.13.0

.PHONY: install demo test bench lint clean

$(STAMP): pyproject.toml Makefile
	test -x $(BIN)/python || $(PY) -m venv $(VENV)
	# Elsewhere: PyTorch's CPU wheel index first (PyPI's Linux wheels carry CUDA, several GB).
	$(BIN)/pip install -q --disable-pip-version-check $(TORCH_SPEC) \
		|| $(BIN)/pip install -q "torch>=2.2,<2.15" --index-url https://download.pytorch.org/whl/cpu \
		|| $(BIN)/pip install -q "torch>=2.2,<2.15"
	# compat mode: a plain .pth entry; the default editable finder cost ~35 ms on every command
	$(BIN)/pip install -q --disable-pip-version-check -e '.[test]' --config-settings editable_mode=compat
	touch $(STAMP)

# The viewer plugin (`zooctl view`): nothing beyond zooctl (its three.js is vendored in it).
$(VIEWER_STAMP): $(STAMP) plugins/zooctl-viewer/pyproject.toml
	$(BIN)/pip install -q --disable-pip-version-check --no-deps -e plugins/zooctl-viewer --config-settings editable_mode=compat
	touch $(VIEWER_STAMP)

# Blender as a Python module, only for the tests that open our exports in Blender (~350 MB).
# The ray executor plugin (pulls ray, ~200 MB installed) after torch, so torch's pin stands.
$(TEST_STAMP): $(STAMP) $(VIEWER_STAMP) plugins/zooctl-ray/pyproject.toml
	$(BIN)/pip install -q --disable-pip-version-check bpy==4.2.0 || echo "bpy unavailable: Blender tests will skip"
	$(BIN)/pip install -q --disable-pip-version-check -e plugins/zooctl-ray || echo "ray unavailable: Ray tests will skip"
	touch $(TEST_STAMP)

install: $(STAMP)

demo: $(STAMP) $(VIEWER_STAMP)
	$(BIN)/python -m zooctl.demo

test: $(TEST_STAMP)
	$(BIN)/python -m pytest -q -p no:cacheprovider -n 2 --dist loadfile --durations=15

# The quick benchmarks; bench/{video,retrieval,fit,motion,embed}.py are longer runs (see BENCHMARKS.md).
bench: $(STAMP)
	$(BIN)/python bench/bank.py
	$(BIN)/python bench/render.py --threads 1
	$(BIN)/python bench/export.py

# vulture: dead code (settings in pyproject.toml, false positives in tools/vulture_whitelist.py)
lint: $(STAMP)
	$(BIN)/ruff check zooctl tests bench plugins tools
	$(BIN)/ruff format --check zooctl tests bench plugins tools
	$(BIN)/vulture

clean:
	rm -rf $(VENV) build *.egg-info
