#!/usr/bin/env bash
# Render report pages (index.html) in headless Chromium to PNG and fail if
# the page or one of its images does not load, or Chromium logs an error.
# Also fails on a caption sentence that starts in lowercase (the rule of
# dynocomp::report::page::lowercase_sentence_starts).
# Installs Debian's `chromium` (apt-get, as root or via sudo) when missing.
# Usage: scripts/render_check.sh PAGE.html [PAGE.html ...]  (PNG next to each page)
set -euo pipefail
[ $# -ge 1 ] || { echo "usage: $0 PAGE.html..." >&2; exit 2; }
if ! command -v chromium >/dev/null; then
    sudo_=""; [ "$(id -u)" = 0 ] || sudo_="sudo"
    $sudo_ apt-get update -qq && $sudo_ apt-get install -y -qq chromium >/dev/null
fi
flags=(--headless --no-sandbox --disable-gpu --disable-quic --no-first-run --disable-background-networking
       --disable-component-update --disable-sync --hide-scrollbars --allow-file-access-from-files)
fail=0
for page in "$@"; do
    [ -f "$page" ] || { echo "render_check: $page: no such page" >&2; fail=1; continue; }
    abs="$(cd "$(dirname "$page")" && pwd)/$(basename "$page")"
    png="${abs%.html}.png"
    prof="$(mktemp -d)"
    log="$(mktemp)"
    # Every <img> must have loaded with a size: the DOM after load records it.
    chromium "${flags[@]}" --user-data-dir="$prof" --virtual-time-budget=5000 --run-all-compositor-stages-before-draw \
        --dump-dom "file://$abs" >"$log.dom" 2>"$log" || { echo "render_check: $page: chromium failed" >&2; cat "$log" >&2; fail=1; }
    rm -rf "$prof"; prof="$(mktemp -d)"
    chromium "${flags[@]}" --user-data-dir="$prof" --window-size=1200,2400 --screenshot="$png" --enable-logging=stderr --v=0 \
        "file://$abs" >>"$log" 2>&1 || { echo "render_check: $page: screenshot failed" >&2; fail=1; }
    rm -rf "$prof"
    n_img=$(grep -o '<img ' "$log.dom" | wc -l)
    # Missing images (or SVG parse errors) are reported on the console.
    if grep -E 'ERR_FILE_NOT_FOUND|Failed to load resource|Uncaught|error on line' "$log" >&2; then
        echo "render_check: $page: errors while loading (above)" >&2; fail=1
    fi
    for src in $(grep -o 'src="[^"]*"' "$abs" | sed 's/src="//;s/"$//'); do
        f="$(dirname "$abs")/$src"
        if [ ! -s "$f" ]; then echo "render_check: $page: image $src missing" >&2; fail=1; continue; fi
        if command -v xmllint >/dev/null && [[ "$src" == *.svg ]] && ! xmllint --noout "$f" 2>&1 >&2; then
            echo "render_check: $page: $src is not well-formed SVG" >&2; fail=1
        fi
    done
    lower=$(perl -CSD -0777 -ne '
        while (/<p class="caption">(.*?)<\/p>/gs) {
            my $c = $1; $c =~ s/&lt;/</g; $c =~ s/&gt;/>/g; $c =~ s/&quot;/"/g; $c =~ s/&#39;/\x27/g; $c =~ s/&amp;/&/g;
            # sentence starts: the caption start, and after . ! ? and a space (not after e.g. i.e. cf. vs. etc.)
            while ($c =~ / (?: ^ | (?<![ (]e\.g\.) (?<![ (]i\.e\.) (?<![ (]cf\.) (?<![ (]vs\.) (?<![ (]etc\.)
                               (?<=[.!?]) \s )
                           \s* (\p{Ll}\S* (?:\s+\S+){0,3}) /gx) {
                print "$1\n";
            }
        }' "$abs" 2>&1)
    if [ -n "$lower" ]; then
        echo "render_check: $page: caption sentences start in lowercase:" >&2
        echo "$lower" | sed 's/^/  /' >&2; fail=1
    fi
    if [ ! -s "$png" ] || [ "$n_img" -eq 0 ]; then echo "render_check: $page: no screenshot or no images rendered" >&2; fail=1; fi
    echo "render_check: $page -> $png ($n_img images)"
    rm -f "$log" "$log.dom"
done
exit $fail
