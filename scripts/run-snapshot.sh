#!/usr/bin/env bash
# Carries an interrupted training run between machines through the repository: `save` copies
# what `lfnet train --resume` needs from a run folder (config.json, training.jsonl, every
# finished stage's model, and the unfinished stage's last.ckpt and best.ckpt) into a folder
# that can be committed; `restore` puts it back as a run folder. Nothing else of the run
# folder is needed to resume (docs/training.md, "Long runs across machines").
# Usage: scripts/run-snapshot.sh save RUN_DIR SNAPSHOT_DIR
#        scripts/run-snapshot.sh restore SNAPSHOT_DIR RUN_DIR
set -euo pipefail
cd "$(dirname "$0")/.."
usage() {
  echo "usage: $0 save RUN_DIR SNAPSHOT_DIR | restore SNAPSHOT_DIR RUN_DIR" >&2
  exit 2
}
[[ $# -eq 3 ]] || usage
mode=$1 from=${2%/} to=${3%/}
[[ -f $from/config.json ]] || {
  echo "run-snapshot: error: $from/config.json does not exist: not a run folder" >&2
  exit 1
}
case $mode in
  save)
    tmp="$to.tmp.$$"
    rm -rf "$tmp"
    mkdir -p "$tmp/models"
    cp "$from/config.json" "$tmp/"
    [[ -f $from/training.jsonl ]] && cp "$from/training.jsonl" "$tmp/"
    for model in "$from"/models/*.ckpt; do
      [[ -e $model ]] && cp "$model" "$tmp/models/"
    done
    for dir in "$from"/models/*/; do
      stage=$(basename "$dir")
      # A finished stage resumes from its model; only an unfinished one needs its state.
      [[ -f $from/models/$stage.ckpt ]] && continue
      mkdir -p "$tmp/models/$stage"
      for f in last.ckpt best.ckpt; do
        [[ -f $dir/$f ]] && cp "$dir/$f" "$tmp/models/$stage/"
      done
    done
    rm -rf "$to"
    mkdir -p "$(dirname "$to")"
    mv "$tmp" "$to"
    echo "run-snapshot: saved $from to $to ($(du -sh "$to" | cut -f1))"
    ;;
  restore)
    if [[ -e $to ]]; then
      echo "run-snapshot: error: $to exists; remove it first or resume it as it is" >&2
      exit 1
    fi
    mkdir -p "$(dirname "$to")"
    cp -r "$from" "$to.tmp.$$"
    mv "$to.tmp.$$" "$to"
    echo "run-snapshot: restored $from to $to"
    ;;
  *) usage ;;
esac
