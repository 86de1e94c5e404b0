#!/usr/bin/env bash
# Text checks of the repository (run by scripts/check.sh before anything is compiled):
# - no tracked text file points the reader to documents that are not in the repository, or
#   speaks of how the code was produced instead of what it does (work logs, tracker
#   numbers, commit hashes in prose): a user who clones the repository has none of that;
# - README.md stays a short user's page (at most 220 lines; the depth is in docs/).
# Prints file:line:text for every hit and exits non-zero if there is any.
set -euo pipefail
cd "$(dirname "$0")/.."

readme_max_lines=220

# Tracked text files: not Cargo.lock, not binary or data files.
files=()
while IFS= read -r f; do
    if [ -f "$f" ]; then files+=("$f"); fi
done < <(git ls-files |
    grep -v -E '(^|/)Cargo\.lock$' |
    grep -v -i -E '\.(lut|csv|bin|png|jpe?g|pgm|ppm|gif|svg|elf|uf2|ttf|otf|pdf|gz|zip)$')
if [ "${#files[@]}" -eq 0 ]; then
    echo "check-words: no tracked files found (needs a git checkout)" >&2
    exit 1
fi

# Case-insensitive extended regular expressions, checked in every file. Each word is
# written with one letter in brackets so that the script does not spell out what it looks
# for: design notes kept outside the repository, references to a work log, to assistants in
# the development process, to tracker entries, and to commits.
patterns=(
    'DESIG[N]\.md|COMMO[N]\.md'
    '\b(this|last|next) sessio[n]\b'
    '\bsessio[n][ -]?[0-9]+'
    '\bsub-?agen[t]s?\b'
    "\b(another|other) helpe[r]\b|\bhelpe[r]'s\b|\bthe \`[a-z_-]+\` helpe[r]\b"
    '\bissu[e]s? #?[0-9]+'
    "\b(the|this|that) issu[e]\b|\bissu[e]'s\b|\bissu[e] (tolerance|targets?|acceptance|criterion)\b"
    '\blande[d]\b'
    '\bcommi[t] [0-9a-f]{7,40}\b'
)

# Markdown and plain-text prose only: tracker references such as "#8", and abbreviated
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
