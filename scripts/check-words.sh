#!/usr/bin/env bash
# Text checks of the repository (run by scripts/check.sh before anything is compiled):
# - no tracked text file refers to documents that are not in the repository (DESIGN.md,
#   COMMON.md) or uses development-process vocabulary (work sessions, agents, issue
#   numbers, commit hashes in prose);
# - README.md stays a short user's page (at most 220 lines; the depth is in docs/).
# Prints file:line:text for every hit and exits non-zero if there is any.
set -euo pipefail
cd "$(dirname "$0")/.."

readme_max_lines=220
self=scripts/check-words.sh

# Tracked text files: not Cargo.lock, not binary or data files, not this script (it holds
# the patterns).
files=()
while IFS= read -r f; do
    if [ -f "$f" ]; then files+=("$f"); fi
done < <(git ls-files |
    grep -v -E '(^|/)Cargo\.lock$' |
    grep -v -i -E '\.(lut|csv|bin|png|jpe?g|pgm|ppm|gif|svg|elf|uf2|ttf|otf|pdf|gz|zip)$' |
    grep -v -x -F "$self")
if [ "${#files[@]}" -eq 0 ]; then
    echo "check-words: no tracked files found (needs a git checkout)" >&2
    exit 1
fi

# Case-insensitive extended regular expressions, checked in every file.
patterns=(
    'DESIGN\.md|COMMON\.md'
    '\b(this|last|next) session\b'
    '\bsession[ -]?[0-9]+'
    '\bsub-?agents?\b'
    "\b(another|other) helper\b|\bhelper's\b|\bthe \`[a-z_-]+\` helper\b"
    '\bissues? #?[0-9]+'
    "\b(the|this|that) issue\b|\bissue's\b|\bissue (tolerance|targets?|acceptance|criterion)\b"
    '\blanded\b'
    '\bcommit [0-9a-f]{7,40}\b'
)

# Markdown and plain-text prose only: issue references such as "#8", and abbreviated commit
# hashes (7 to 12 lowercase hex digits with at least one digit and one letter; full
# 64-digit content hashes do not match).
prose=()
for f in "${files[@]}"; do
    case "$f" in
    *.md | *.txt) prose+=("$f") ;;
    esac
done
prose_patterns=(
    '(^|[[:space:](])#[0-9]+\b'
)
hash_pattern='\b(?=[0-9a-f]*[0-9])(?=[0-9a-f]*[a-f])[0-9a-f]{7,12}\b'

hits=0
report() {
    # $1: grep output (file:line:text), possibly empty
    if [ -n "$1" ]; then
        printf '%s\n' "$1"
        hits=$((hits + $(printf '%s\n' "$1" | wc -l)))
    fi
}

for pattern in "${patterns[@]}"; do
    report "$(grep -H -n -I -i -E -e "$pattern" -- "${files[@]}" || true)"
done
if [ "${#prose[@]}" -gt 0 ]; then
    for pattern in "${prose_patterns[@]}"; do
        report "$(grep -H -n -I -i -E -e "$pattern" -- "${prose[@]}" || true)"
    done
    report "$(grep -H -n -I -P -e "$hash_pattern" -- "${prose[@]}" || true)"
fi

readme_lines=$(wc -l <README.md)
if [ "$readme_lines" -gt "$readme_max_lines" ]; then
    echo "README.md:$readme_lines: README.md has $readme_lines lines (at most $readme_max_lines; move the depth to docs/)"
    hits=$((hits + 1))
fi

if [ "$hits" -gt 0 ]; then
    echo "check-words: $hits problem(s) found" >&2
    exit 1
fi
echo "check-words: ok (${#files[@]} files, README.md $readme_lines lines)"
