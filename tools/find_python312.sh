#!/usr/bin/env sh
# Print the path of a working Python 3.12 interpreter, or fail with one line.
# Order: PYTHON312 from the environment, python3.12 on PATH, pyenv's versions,
# common install prefixes, then uv's managed interpreters.
is312() {
    [ -n "$1" ] && "$1" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 12))' \
        >/dev/null 2>&1
}
for candidate in "${PYTHON312:-}" "$(command -v python3.12 2>/dev/null)"; do
    if is312 "$candidate"; then echo "$candidate"; exit 0; fi
done
if command -v pyenv >/dev/null 2>&1; then
    root=$(pyenv root 2>/dev/null)
    for candidate in "$root"/versions/3.12*/bin/python3.12; do
        if is312 "$candidate"; then echo "$candidate"; exit 0; fi
    done
fi
for candidate in /usr/bin/python3.12 /usr/local/bin/python3.12 \
        /opt/homebrew/bin/python3.12 "$HOME"/.pyenv/versions/3.12*/bin/python3.12; do
    if is312 "$candidate"; then echo "$candidate"; exit 0; fi
done
if command -v uv >/dev/null 2>&1; then
    candidate=$(uv python find 3.12 2>/dev/null)
    if is312 "$candidate"; then echo "$candidate"; exit 0; fi
fi
echo "no Python 3.12 found: install one (pyenv install 3.12, apt install python3.12)" \
    " or set PYTHON312=/path/to/python3.12" >&2
exit 1
