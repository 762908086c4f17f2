#!/usr/bin/env bash
# A part of `make test` and its line of the verdict, or the verdict of every part.
#
#   tests/run_part.sh [--none-ok] NAME RESULTS -- COMMAND...   run COMMAND; "{ledger}" in it
#       becomes the path of the part's ledger (pytest's --ledger, tests/verdict.py); add NAME's
#       line to RESULTS/verdict. Without RESULTS (""), print that line at once. Exit status:
#       COMMAND's; with --none-ok, pytest's 5 (no test selected) is not a failure.
#   tests/run_part.sh --skip NAME RESULTS REASON   a part that cannot run here (not a failure)
#   tests/run_part.sh --verdict RESULTS            print every part's line and the verdict;
#       exit status 1 when a part failed. RESULTS is removed when every part passed.
#
# The line of a part is read from its ledger, not from pytest's output: it is there however
# the part stopped (a test over its limit, a process that ended, the part's own time limit).
set -uo pipefail

# One ledger: "N passed, M failed (...); did not finish: ...; K of L not started" (empty when
# no test ran).
summarise() {
    awk '
    function names(list, n,   text, k) {
        for (k = 1; k <= n && k <= 3; k++) text = text (k > 1 ? ", " : "") list[k]
        return n > 3 ? text sprintf(" and %d more", n - 3) : text
    }
    { what = $1; id = substr($0, length($1) + 2) }
    what == "collected" { collected = id; next }
    what == "start" { if (!(id in running)) { running[id] = 1; started++ }; next }
    what == "end" { next }
    {
        delete running[id]
        if (what == "stuck") { stuck[++nstuck] = id; next }
        count[what]++; done++
        if (what == "failed" || what == "error") failed[++nfailed] = id
    }
    END {
        n = split("passed failed error skipped xfailed xpassed", order, " ")
        for (k = 1; k <= n; k++)
            if (count[order[k]]) text = text (text ? ", " : "") count[order[k]] " " order[k]
        if (nfailed) text = text " (" names(failed, nfailed) ")"
        for (id in running) unfinished[++nunfinished] = id
        for (k = 1; k <= nstuck; k++) unfinished[++nunfinished] = stuck[k] " (over its limit)"
        if (nunfinished) text = text (text ? "; " : "") "did not finish: " \
            names(unfinished, nunfinished)
        if (collected != "" && collected - started > 0)
            text = text (text ? "; " : "") (collected - started) " of " collected " not started"
        print text  # empty: no test ran
    }' "$1"
}

# The line of a part: from its ledgers (one, or one per MPI rank) and the command's status.
part_line() {
    local name=$1 results=$2 status=$3 seconds=$4 none_ok=${5-} text="" ledger verdict=ok
    local found=()
    for ledger in "$results/$name.ledger" "$results/$name.ledger".rank*; do
        [[ -f $ledger ]] && found+=("$ledger")
    done
    if [[ ${#found[@]} -eq 1 ]]; then
        text=$(summarise "${found[0]}")
    elif [[ ${#found[@]} -gt 1 ]]; then
        local first same=1 each
        first=$(summarise "${found[0]}")
        for ledger in "${found[@]:1}"; do
            [[ $(summarise "$ledger") == "$first" ]] || same=0
        done
        if [[ $same -eq 1 ]]; then
            text="${first:+$first (each of ${#found[@]} ranks)}"
        else
            for ledger in "${found[@]}"; do
                each=$(summarise "$ledger")
                text+="${text:+; }rank ${ledger##*.rank}: $each"
            done
        fi
    fi
    case $status in
        0) ;;
        5) text="no test selected"; [[ -n $none_ok ]] || verdict=FAILED ;;
        1) verdict=FAILED ;;
        124 | 137) verdict=FAILED; text+="${text:+; }stopped by the part's time limit" ;;
        *) verdict=FAILED; text+="${text:+; }exit status $status (the output above says why)" ;;
    esac
    [[ -n $text ]] || text="passed"
    printf '%s\t%s\t%s\t%s\n' "$name" "$verdict" "$(clock "$seconds")" "$text"
}

clock() { printf '%d min %02d s' $(( $1 / 60 )) $(( $1 % 60 )); }

show() {  # the lines of RESULTS/verdict as a table
    local name verdict took text
    while IFS=$'\t' read -r name verdict took text; do
        printf '  %-9s %-7s %-12s %s\n' "$name" "$verdict" "$took" "$text"
    done <"$1"
}

case ${1-} in
    --verdict)
        results=$2
        [[ -f $results/verdict ]] || { echo "make test: no part ran"; exit 1; }
        failed=$(awk -F'\t' '$2 == "FAILED"' "$results/verdict" | wc -l)
        total=$(wc -l <"$results/verdict")
        echo
        echo "================================ make test: verdict ================================"
        show "$results/verdict"
        if [[ $failed -eq 0 ]]; then
            echo "make test: passed (every part of $total)"
            rm -rf "$results"
            exit 0
        fi
        echo "make test: FAILED ($failed of $total parts; their ledgers: $results)"
        exit 1 ;;
    --skip)
        line=$(printf '%s\t%s\t%s\t%s\n' "$2" "not run" "-" "$4")
        if [[ -n $3 ]]; then echo "$line" >>"$3/verdict"; else echo "$4"; fi
        exit 0 ;;
esac

none_ok=""
if [[ ${1-} == --none-ok ]]; then none_ok=1; shift; fi
name=$1 results=$2
shift 2
[[ ${1-} == -- ]] && shift
alone=""
if [[ -z $results ]]; then
    results=$(mktemp -d "${TMPDIR:-/tmp}/fenicsx-drape-test.XXXXXX")
    alone=1
fi
cmd=()
for arg in "$@"; do cmd+=("${arg//\{ledger\}/$results/$name.ledger}"); done
echo "== $name: ${cmd[*]}"
start=$SECONDS
"${cmd[@]}"
status=$?
part_line "$name" "$results" "$status" $(( SECONDS - start )) "$none_ok" >>"$results/verdict"
if [[ -n $alone ]]; then
    echo
    show "$results/verdict"
    rm -rf "$results"
fi
[[ $status -eq 5 && -n $none_ok ]] && exit 0
exit "$status"
