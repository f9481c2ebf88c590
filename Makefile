# PersonFollow: every target sets itself up from nothing.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-$(shell cat pyproject.toml | sha1sum | cut -c1-12)

.PHONY: setup browser test bench lint eval clean

setup: $(STAMP)

# Torch first and pinned: an unpinned torch (directly or through stable-baselines3) pulls a
# multi-GB CUDA build. The stamp is keyed on pyproject.toml, so a re-run with nothing changed
# skips the install. Editable in setuptools' compat mode (the clone's folder on sys.path): in
# its default mode a folder named policies/, eval/ or train/ where a script runs hides the
# package of that name (Python's own search finds the folder first).
$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet torch==2.13.0
	$(BIN)/python -m pip install --quiet -e '.[dev]' --config-settings editable_mode=compat
	rm -f $(VENV)/.installed-*
	touch $@

# The monitor's browser test drives the system Chromium through playwright (which never
# downloads a browser here). Installed from the distribution's packages when missing and this
# is a root shell with apt-get (CI); elsewhere install it yourself, or the test is skipped and
# says why.
browser:
	@command -v chromium >/dev/null 2>&1 || command -v chromium-browser >/dev/null 2>&1 || \
	{ [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1 && \
	  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null; } || \
	echo "note: no chromium and no root apt-get here: the monitor's browser test will be skipped"

# The simulation kernels compile once per source version, one to two minutes each: compiled
# here side by side, one per core, instead of one after another inside the tests.
test: $(STAMP) browser
	$(BIN)/python -m follow_env.tasks.warm
	$(BIN)/python -m pytest

bench: $(STAMP)
	$(BIN)/python -m bench

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

# The thesis comparison (SPEC.md §1.6): every law and the shipped PPO agent x both conditions
# x 20 seeds, identical rollouts. Prints the table and says where the files went. Override with
# EVAL_ARGS="...".
EVAL_ARGS ?= --policies pn,mpn,gsmpn,ppo --scenarios straight,curve --episodes 20 --seed 0
eval: $(STAMP)
	$(BIN)/follow-eval run $(EVAL_ARGS) --out runs/eval-$$(date +%Y%m%d-%H%M%S)

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache
