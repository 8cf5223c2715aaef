# Set-up is two commands: `make demo` and `make test` (see README).
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: venv demo test bench clean

venv: $(STAMP)

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --upgrade pip
	$(PY) -m pip install -e '.[test]'
	touch $(STAMP)

demo: $(STAMP)
	$(PY) scripts/demo.py

test: $(STAMP)
	$(VENV)/bin/lint-imports
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .
	$(PY) -m pytest -q

bench: $(STAMP)
	$(PY) bench/bench_skeleton_parse.py
	$(PY) bench/bench_training.py
	$(PY) bench/bench_onnx_latency.py
	$(PY) bench/bench_readers.py
	$(PY) bench/bench_casia_b_render.py
	$(PY) bench/bench_gei.py
	$(PY) bench/bench_gait_training.py
	$(PY) bench/bench_nmf.py
	$(PY) bench/bench_retrieval.py --onnx checkpoints/retrieval_supcon/fold_bd/model.onnx --hnsw-max 100000
	$(PY) bench/bench_kinect_corrector.py

clean:
	rm -rf .demo build *.egg-info
