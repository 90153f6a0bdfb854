#!/usr/bin/env bash
# The README's commands still run: every `touchdown SUBCOMMAND` the README names answers
# `--help`, the scripts it names exist (shell scripts executable), and `cargo replay` (the main job's
# alias) is still defined. Part of CI's docs step (docs/ci.md).
#
# usage: scripts/check_readme_commands.sh [TOUCHDOWN]   (default: target/debug/touchdown,
# built if missing)
set -euo pipefail
repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$repo"
touchdown=${1:-target/debug/touchdown}
if [ ! -x "$touchdown" ]; then
    cargo build --quiet -p touchdown-cli
fi
status=0
# Named in code: `touchdown NAME ...` at the start of a code span.
subcommands=$(grep -o '`touchdown [a-z][a-z-]*' README.md | awk '{print $2}' | sort -u)
for sub in $subcommands; do
    if ! "$touchdown" "$sub" --help >/dev/null 2>&1; then
        echo "README.md names \`touchdown $sub\`, which does not answer --help"
        status=1
    fi
done
for script in $(grep -o 'scripts/[A-Za-z0-9_.-]*\.\(sh\|py\)' README.md | sort -u); do
    # Shell scripts are run directly, Python ones with python3.
    case "$script" in
        *.sh) [ -x "$script" ] || { echo "README.md names ${script}, which is not an executable file"; status=1; } ;;
        *) [ -f "$script" ] || { echo "README.md names ${script}, which does not exist"; status=1; } ;;
    esac
done
if ! grep -q '^replay *=' .cargo/config.toml; then
    echo "README.md's main job uses \`cargo replay\`, which .cargo/config.toml no longer defines"
    status=1
fi
if [ "$status" = 0 ]; then
    echo "README commands: $(echo "$subcommands" | wc -w) touchdown subcommands answer --help; scripts and the replay alias exist"
fi
exit "$status"
