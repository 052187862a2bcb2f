#!/usr/bin/env bash
# Two hosts for real: each rank in a network namespace of its own, joined by a veth pair, so the
# ranks see each other only through a real interface, and a link can be cut without a FIN or an
# RST (the peer just stops answering). Checks `lfnet train` and `lfnet batch` across the two
# against one process, then the faults of docs/distributed.md ("Faults between hosts"):
#   1. the link of rank 1's host cut mid-epoch; `train --resume` continues the run
#   2. rank 0, which holds the store, killed mid-epoch
#   3. a rank that joins late (the job goes on), a rank that never joins, a rank 0 that never starts
#   4. rank 1 killed mid-batch, `batch --resume` does only what is missing
#   5. the link of rank 1's host cut mid-batch
# Prints a table of every fault (what each rank printed, seconds to exit) and the scaling
# figures; with LFNET_TWO_HOSTS_REPORT=FILE it also writes them there (docs/distributed.md).
#
# Usage: two_hosts.sh LFNET_BINARY
# Exit 77 (CTest: skipped, with the reason printed) where network namespaces cannot be made:
# not root, no `ip`, or a container that forbids them.
set -uo pipefail
lfnet=$(realpath "$1")
timeout_s=15  # --dist-timeout of every job: a silent rank is named within this

skip() {
  echo "SKIPPED: $*"
  exit 77
}
[[ $(id -u) -eq 0 ]] || skip "network namespaces need root (ip netns add)"
command -v ip >/dev/null || skip "no 'ip' command (Debian package iproute2)"

tag=$$
ns0=lfnet$tag-a ns1=lfnet$tag-b
if0=lfa$tag if1=lfb$tag
addr0=10.213.$((tag % 200)).1 addr1=10.213.$((tag % 200)).2
tmp=$(mktemp -d)
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill -9 "$p" 2>/dev/null; done
  ip netns del "$ns0" 2>/dev/null
  ip netns del "$ns1" 2>/dev/null
  rm -rf "$tmp"
}
trap cleanup EXIT
trap 'exit 1' INT TERM  # through the EXIT trap: the namespaces go with the test
if ! ip netns add "$ns0" 2>"$tmp/err"; then
  skip "cannot make a network namespace here: $(head -n 1 "$tmp/err")"
fi
ip netns add "$ns1" || skip "cannot make a second network namespace"
ip link add "$if0" netns "$ns0" type veth peer name "$if1" netns "$ns1" 2>"$tmp/err" ||
  skip "cannot make a veth pair: $(head -n 1 "$tmp/err")"
ip -n "$ns0" addr add "$addr0/24" dev "$if0"
ip -n "$ns1" addr add "$addr1/24" dev "$if1"
for n in "$ns0" "$ns1"; do ip -n "$n" link set lo up; done
ip -n "$ns0" link set "$if0" up
ip -n "$ns1" link set "$if1" up

failures=0
check() {  # check DESCRIPTION COMMAND...
  if "${@:2}"; then
    echo "ok: $1"
  else
    echo "FAILED: $1"
    failures=$((failures + 1))
  fi
}
port=$((20000 + tag % 20000))
next_port() { port=$((port + 1)); }
# on_host N ARGS...: lfnet as rank N of 2 on host N (in the background; its pid in $!).
on_host() {
  local n=$1
  shift
  local ns=$ns0 iface=$if0
  [[ $n == 1 ]] && ns=$ns1 iface=$if1
  ip netns exec "$ns" "$lfnet" --threads 1 "$@" --world-size 2 --rank "$n" \
    --master "$addr0:$port" --dist-interface "$iface" --dist-timeout "$timeout_s" &
}
# wait_for FILE PATTERN SECONDS: until FILE holds PATTERN.
wait_for() {
  for _ in $(seq $(($3 * 10))); do
    grep -q "$2" "$1" 2>/dev/null && return 0
    sleep 0.1
  done
  return 1
}
# finish PID: its exit status; the seconds since $start in $took.
finish() {
  wait "$1"
  local rc=$?
  took=$(($(date +%s) - start))
  return $rc
}
error_line() { grep -m1 'lfnet: error:' "$1" | sed 's/.*lfnet: error: //'; }
# job NAME OUT0 OUT1 ARGS...: ranks 0 and 1 of one job on a fresh port, logs NAME0.log and
# NAME1.log, pids in p0 and p1.
job() {
  local name=$1 out0=$2 out1=$3
  shift 3
  next_port
  on_host 0 "$@" --out "$out0" >"${name}0.log" 2>&1
  p0=$!
  on_host 1 "$@" --out "$out1" >"${name}1.log" 2>&1
  p1=$!
  pids+=("$p0" "$p1")
}
# cut_link WHAT NAME BOUND: cuts the link of rank 1's host under job NAME; both ranks must exit
# non-zero within BOUND seconds, each naming the other. Their times in t0 and t1; the link
# comes back up.
cut_link() {
  ip -n "$ns1" link set "$if1" down
  start=$(date +%s)
  finish "$p0"
  rc0=$?
  t0=$took
  finish "$p1"
  rc1=$?
  t1=$took
  check "$1: rank 0 names rank 1 (${t0} s)" grep -q "rank 0 of 2: .*rank 1 stopped answering" "${2}0.log"
  check "$1: rank 1 names rank 0 (${t1} s)" \
    grep -q "rank 1 of 2: .*rank 0, which holds the job's store, stopped answering" "${2}1.log"
  check "$1: both exit non-zero within $3 s" \
    test "$rc0" -ne 0 -a "$rc1" -ne 0 -a "$t0" -le "$3" -a "$t1" -le "$3"
  ip -n "$ns1" link set "$if1" up
}
# first_item_of_rank1 OUT: until rank 1 (items 2, 4, ...) has recorded its first item.
first_item_of_rank1() {
  for _ in $(seq 1200); do
    compgen -G "$1/records/lf_02__*" >/dev/null && return 0
    sleep 0.05
  done
  return 1
}
table=()
row() { table+=("| $1 | $2 | $3 | $4 | $5 |"); }

cd "$tmp" || exit 1

# ---- data --------------------------------------------------------------------------------
config() {  # config EPOCHS PATCHES
  cat <<EOF
{
  "name": "hosts", "phi": "asp:2",
  "data": {"random_scenes": 2, "random_seed": 5, "random_options": {"height": 64, "width": 64}},
  "dataset": {"train_patches": $2, "validation_patches": 64, "seed": 2},
  "network": {"paper": {"residual": "pinv", "cnn": {"channels": 4}}},
  "training": {"epochs": $1, "batch_size": 32, "progress": false},
  "stages": ["cnn"]
}
EOF
}
config 2 256 >short.json
config 12 512 >long.json
for k in $(seq 10); do
  "$lfnet" --log-level warn render --random "$k" --size 144x180 --views 5x5 --grey \
    --out "items/lf_$(printf %02d "$k")" || exit 1
done
batch_args="batch --input items --phi asp:2 --methods pinv,no-parallax --stride 3"

# ---- 1. equivalence: train and batch on two hosts against one process ---------------------
"$lfnet" --threads 1 --log-level warn train short.json --out one >one.log 2>&1
check "one-process training" test -f one/models/cnn.ckpt
start=$(date +%s)
on_host 0 train short.json --out two >two0.log 2>&1
p0=$!
pids+=("$p0")
sleep 3 # rank 1 joins late: the job waits for it
on_host 1 train short.json --out two-rank1 >two1.log 2>&1
p1=$!
pids+=("$p1")
finish "$p0"
rc0=$?
finish "$p1"
rc1=$?
train_two_s=$took
check "two-host training ends well on both ranks (rank 1 joined 3 s late)" test "$rc0$rc1" = 00
check "only rank 0 writes the run" test ! -e two-rank1/training.jsonl
row "rank 1 joins 3 s late" "rendezvous" "-" "-" "both ranks trained to the end"
/usr/bin/python3 - one/training.jsonl two/training.jsonl <<'PY' >compare.log 2>&1
import json, sys
a = [json.loads(l)["record"] for l in open(sys.argv[1])]
b = [json.loads(l)["record"] for l in open(sys.argv[2])]
assert len(a) == len(b) == 2, (len(a), len(b))
for x, y in zip(a, b):
    for k in ("train_loss", "val_loss"):
        rel = abs(x[k] - y[k]) / max(abs(x[k]), 1e-12)
        print(f"epoch {x['epoch']} {k}: one {x[k]:.8g} two hosts {y[k]:.8g} relative {rel:.2e}")
        assert rel < 1e-4, k
PY
check "two hosts train as one process does (losses within 1e-4 relative)" test $? -eq 0
cat compare.log

start=$(date +%s.%N)
"$lfnet" --threads 1 --log-level warn $batch_args --out batch-one >batch-one.log 2>&1
batch_one_s=$(awk "BEGIN { print $(date +%s.%N) - $start }")
check "one-process batch" test -f batch-one/summary.csv
start=$(date +%s)
batch_start=$(date +%s.%N)
job b batch-two batch-two $batch_args
finish "$p0"
rc0=$?
finish "$p1"
rc1=$?
batch_two_s=$(awk "BEGIN { print $(date +%s.%N) - $batch_start }")
check "two-host batch ends well" test "$rc0$rc1" = 00
# The summaries agree but for the seconds column (the 7th).
same_summary() { diff <(cut -d, -f1-6,8- "$1") <(cut -d, -f1-6,8- "$2") >/dev/null; }
check "two hosts' batch summary equals one process's" same_summary batch-one/summary.csv \
  batch-two/summary.csv

# ---- 2. the link of rank 1's host cut mid-epoch ----------------------------------------------
job cut cut cut-rank1 train long.json
wait_for cut0.log "epoch 2:" 120
sleep 0.5
cut_link "cut link, training" cut $((timeout_s + 10))
epochs_before=$(wc -l <cut/training.jsonl)
"$lfnet" --threads 1 --log-level warn train --resume cut >cut-resume.log 2>&1
check "cut link: train --resume continues from epoch $epochs_before to the end" \
  test "$(wc -l <cut/training.jsonl)" -eq 12
row "link of rank 1's host cut" "training, epoch $((epochs_before + 1))" \
  "rank 0 ($t0 s): $(error_line cut0.log)" "rank 1 ($t1 s): $(error_line cut1.log)" \
  "\`train --resume\` from epoch $epochs_before of 12: $(wc -l <cut/training.jsonl) epochs"

# ---- 3. rank 0, holding the store, killed mid-epoch ---------------------------------------
job kill killed killed-rank1 train long.json
wait_for kill0.log "epoch 1:" 120
sleep 0.5
kill -9 "$p0"
wait "$p0" 2>/dev/null
start=$(date +%s)
finish "$p1"
rc1=$?
t1=$took
check "store killed: rank 1 fails naming rank 0 (${t1} s)" grep -q "rank 1 of 2: .*rank 0, which holds the job's store, stopped answering" kill1.log
check "store killed: within 10 s" test "$rc1" -ne 0 -a "$t1" -le 10
epochs_before=$(wc -l <killed/training.jsonl)
"$lfnet" --threads 1 --log-level warn train --resume killed >kill-resume.log 2>&1
check "store killed: train --resume continues to the end" test "$(wc -l <killed/training.jsonl)" -eq 12
row "rank 0 (the store) killed" "training, epoch $((epochs_before + 1))" "killed" \
  "rank 1 ($t1 s): $(error_line kill1.log)" \
  "\`train --resume\` from epoch $epochs_before of 12: $(wc -l <killed/training.jsonl) epochs"

# ---- 4. ranks that never join --------------------------------------------------------------
next_port
start=$(date +%s)
on_host 0 train short.json --out alone >alone0.log 2>&1
finish $!
rc0=$?
t0=$took
check "rank 1 never joins: rank 0 names it (${t0} s)" grep -q "rank 0 of 2: rank 1 did not join within $timeout_s s" alone0.log
check "rank 1 never joins: nothing is left behind" test ! -e alone
next_port
start=$(date +%s)
on_host 1 train short.json --out alone1 >alone1.log 2>&1
finish $!
rc1=$?
t1=$took
check "rank 0 never starts: rank 1 names its store (${t1} s)" grep -q "rank 1 of 2: the job's store at $addr0:$port (rank 0) did not answer within $timeout_s s" alone1.log
check "never joined: both exit non-zero within --dist-timeout + 10 s" \
  test "$rc0" -ne 0 -a "$rc1" -ne 0 -a "$t0" -le $((timeout_s + 10)) -a "$t1" -le $((timeout_s + 10))
row "rank 1 never starts" "rendezvous" "rank 0 ($t0 s): $(error_line alone0.log)" "-" "nothing to resume; no run folder left"
row "rank 0 never starts" "rendezvous" "-" "rank 1 ($t1 s): $(error_line alone1.log)" "nothing to resume"

# ---- 5. rank 1 killed mid-batch; batch --resume does the rest --------------------------------
job bk batch-kill batch-kill $batch_args
first_item_of_rank1 batch-kill
kill -9 "$p1"
wait "$p1" 2>/dev/null
start=$(date +%s)
finish "$p0"
rc0=$?
t0=$took
records_before=$(ls batch-kill/records | wc -l)
check "batch, rank 1 killed: rank 0 fails naming rank 1 (${t0} s)" grep -q "rank 0 of 2: .*rank 1 stopped answering" bk0.log
check "batch, rank 1 killed: some but not all records were written ($records_before of 20)" \
  test "$records_before" -gt 0 -a "$records_before" -lt 20
ls -l --time-style=+%s.%N batch-kill/records | awk '{print $6, $7}' | sort >records-before.txt
"$lfnet" --threads 1 $batch_args --out batch-kill --resume >bk-resume.log 2>&1
check "batch --resume ends well" test $? -eq 0
todo=$(grep -o '[0-9]* item(s) to do' bk-resume.log | cut -d' ' -f1)
check "batch --resume does only the $(( (20 - records_before) / 2 )) missing item(s) (did ${todo:-?})" \
  test "${todo:-x}" -eq $(((20 - records_before) / 2))
ls -l --time-style=+%s.%N batch-kill/records | awk '{print $6, $7}' | sort >records-after.txt
kept_untouched() { [[ -z $(comm -23 records-before.txt records-after.txt) ]]; }
check "batch --resume rewrites none of the records written before" kept_untouched
check "batch --resume: the summary equals one process's" same_summary batch-one/summary.csv \
  batch-kill/summary.csv
row "rank 1 killed" "batch, after its first item" "rank 0 ($t0 s): $(error_line bk0.log)" "killed" \
  "\`batch --resume\`: $records_before of 20 records kept, $todo item(s) done; 0 lost, 0 twice"

# ---- 6. the link of rank 1's host cut mid-batch ----------------------------------------------
job bc batch-cut batch-cut $batch_args
first_item_of_rank1 batch-cut
# Rank 1 goes on with its items, which need no network, and fails at the gather.
cut_link "cut link, batch" bc $((timeout_s + 30))
records_before=$(ls batch-cut/records | wc -l)
"$lfnet" --threads 1 $batch_args --out batch-cut --resume >bc-resume.log 2>&1
check "batch --resume after the cut ends well" test $? -eq 0
todo=$(grep -o '[0-9]* item(s) to do' bc-resume.log | cut -d' ' -f1)
check "batch --resume after the cut: the summary equals one process's" same_summary \
  batch-one/summary.csv batch-cut/summary.csv
row "link of rank 1's host cut" "batch, after its first item" "rank 0 ($t0 s): $(error_line bc0.log)" \
  "rank 1 ($t1 s): $(error_line bc1.log)" \
  "\`batch --resume\`: $records_before of 20 records kept, ${todo:-?} item(s) done; 0 lost, 0 twice"

# ---- figures -------------------------------------------------------------------------------
scaling=$(/usr/bin/python3 - one/training.jsonl two/training.jsonl "$train_two_s" \
  batch-one/summary.json "$batch_two_s" <<'PY'
import json, sys
one = [json.loads(l)["record"] for l in open(sys.argv[1])]
two = [json.loads(l)["record"] for l in open(sys.argv[2])]
print("| training (`short.json`, 256 patches an epoch) | epoch | patches/s | collectives, % of training time |")
print("|---|---:|---:|---:|")
for name, rs in (("1 process", one), ("2 hosts", two)):
    for r in rs:
        train_s = 256 / r["patches_per_s"]
        share = 100 * r.get("communication_s", 0) / train_s
        print(f"| {name} | {r['epoch']} | {r['patches_per_s']:.1f} | {share:.1f} |")
PY
)
report() {
  echo "### Faults between two hosts (network namespaces, --dist-timeout $timeout_s)"
  echo
  echo "| fault | where it struck | rank 0 printed | rank 1 printed | resumed |"
  echo "|---|---|---|---|---|"
  printf '%s\n' "${table[@]}"
  echo
  echo "### Scaling (two namespaces on one machine, one thread per rank)"
  echo
  echo "$scaling"
  echo
  echo "| batch (10 light fields, pinv and no-parallax) | wall seconds, start to summary | items/s |"
  echo "|---|---:|---:|"
  printf '| 1 process | %.2f | %.2f |\n' "$batch_one_s" "$(awk "BEGIN { print 10 / $batch_one_s }")"
  printf '| 2 hosts | %.2f | %.2f |\n' "$batch_two_s" "$(awk "BEGIN { print 10 / $batch_two_s }")"
}
report
[[ -n ${LFNET_TWO_HOSTS_REPORT:-} ]] && report >"$LFNET_TWO_HOSTS_REPORT"
if [[ $failures -gt 0 ]]; then
  for f in *.log; do
    echo "---- $f"
    tail -n 5 "$f"
  done
fi
echo "two_hosts: $failures check(s) failed"
[[ $failures -eq 0 ]]
