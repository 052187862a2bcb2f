# shellcheck shell=bash
# Steps shared by the scripts that train models into models/ one step at a time
# (lfnet-models.sh, noise-models.sh, paper-scale.sh). Sourced, not run.

# Says whether step $1's model file $2 exists already (then the step is skipped) or is trained now.
model_exists() {
  if [[ -f $2 ]]; then
    echo "== $1: $2 exists, skipped"
    return 0
  fi
  echo "== $1: training ($(date -u +%H:%M))"
  return 1
}

# Copies the newest stage model of run folder $1 to $2, whole or not at all.
keep_model() {
  mkdir -p "$(dirname "$2")"
  cp "$(ls -t "$1"/models/*.ckpt | head -n1)" "$2.tmp"
  mv "$2.tmp" "$2"
}
