# Sourced by scripts/demo and scripts/test: create .venv and install the project into it (with the extras
# named in VENV_EXTRAS, e.g. "test") when missing or older than pyproject.toml.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
PYTHON="${PYTHON:-python3}"
if ! "$PYTHON" -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null; then
  echo "visuotactile needs Python 3.11 or newer; '$PYTHON' is $("$PYTHON" --version 2>&1 || echo missing)." >&2
  echo "Set PYTHON=/path/to/python3.11 and run again." >&2
  exit 1
fi
marker=".venv/.installed${VENV_EXTRAS:+-$VENV_EXTRAS}"
# A current set-up with every extra asked for serves too: the test set-up ("test,docs") serves the demo and the docs.
for installed in .venv/.installed*; do
  [ -f "$installed" ] && [ ! pyproject.toml -nt "$installed" ] || continue
  have=",${installed#.venv/.installed-},"
  missing=""
  for extra in ${VENV_EXTRAS:+${VENV_EXTRAS//,/ }}; do [[ "$have" == *",$extra,"* ]] || missing=1; done
  if [ -z "$missing" ]; then marker=$installed; break; fi
done
if [ ! -f "$marker" ] || [ pyproject.toml -nt "$marker" ]; then
  echo "setting up .venv (once) ..." >&2
  if [ ! -x .venv/bin/python ]; then
    "$PYTHON" -m venv .venv
    .venv/bin/python -m pip install --quiet --upgrade pip
  fi
  # Bytecode is compiled as modules are first imported: compiling every installed file up front
  # costs 11 of the 26 s of the install, for files the toolkit never imports.
  .venv/bin/python -m pip install --quiet --no-compile -e ".${VENV_EXTRAS:+[$VENV_EXTRAS]}"
  # Where PYTHONDONTWRITEBYTECODE is set, as on CI machines, no process writes bytecode, and each one (the
  # CLI, every worker, every test's subprocess) would compile what it imports again: 2.5 of its 4.4 s of
  # imports.  So the bytecode of what the toolkit imports is written once, here.
  modules="classify.cli, classify.experiment.run, meshsal.points, meshsal.attention.rig, meshsal.objects.instances"
  if [[ ",${VENV_EXTRAS:-}," == *,test,* ]]; then modules="$modules, classify.experiment.env, distributed, pytest, xdist"; fi
  env -u PYTHONDONTWRITEBYTECODE .venv/bin/python -c "import $modules"
  touch "$marker"
fi
