#!/usr/bin/env bash
# graspkit's two commands, on a fresh machine with only Python 3.11 and pip:
#   bash workbook.sh demo   # set up .venv, then run the main job (figures etc. into outputs/demo)
#   bash workbook.sh test   # set up .venv, then run the whole test suite: pytest + nbval over notebooks/
set -euo pipefail
cd "$(dirname "$0")"
VENV="${GRASPKIT_VENV:-.venv}"
TORCH_SPEC="${GRASPKIT_TORCH:-torch==2.13.0}"   # the CPU build on this project's machines; GRASPKIT_TORCH for another (README)

setup() {
  [ -x "$VENV/bin/python" ] || python3 -m venv "$VENV"
  local stamp="$VENV/.graspkit-installed" want
  want="$(cat pyproject.toml; echo "$TORCH_SPEC")"
  if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
    "$VENV/bin/python" -m pip install -q --disable-pip-version-check "$TORCH_SPEC"
    "$VENV/bin/python" -m pip install -q --disable-pip-version-check -e ".[test]"
    printf '%s' "$want" > "$stamp"
  fi
}

case "${1:-}" in
  demo) setup; shift; MPLBACKEND="${MPLBACKEND:-Agg}" "$VENV/bin/graspkit" demo --out outputs/demo "$@" ;;
  test) setup; shift
        export MPLBACKEND=Agg
        # two workers (the machine's two cores), each test module and each notebook whole on one of them
        "$VENV/bin/python" -m pytest -q -n "${GRASPKIT_TEST_WORKERS:-2}" --dist loadscope tests notebooks --nbval --nbval-current-env \
          --nbval-sanitize-with notebooks/sanitize.cfg --nbval-cell-timeout 600 "$@" ;;
  *) echo "usage: bash workbook.sh {demo|test} [extra args]" >&2; exit 2 ;;
esac
