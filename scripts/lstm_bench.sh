#!/usr/bin/env bash
# Full-epoch throughput of seqnet next to PyTorch's nn.LSTM (2 threads), same data recipe:
# 50,000 samples, 10 inputs -> 12 outputs, LSTM(64) + dense head, Adam 1e-3, batch 256.
#
# Usage (from the workspace root):  scripts/lstm_bench.sh [epochs] [--no-torch]
# Not run in CI. Needs Python with numpy + torch for the PyTorch half
# (/work/shared/anchors/lstm_anchor.py, or $LSTM_ANCHOR).
set -euo pipefail
cd "$(dirname "$0")/.."
EPOCHS="${1:-5}"
cargo build --release -q -p seqnet --example lstm_epoch
BIN="${CARGO_TARGET_DIR:-target}/release/examples/lstm_epoch"
echo "# seqnet ($EPOCHS epochs each; median epoch time)"
for steps in 10 1; do
  for threads in 1 2; do
    "$BIN" "$steps" "$threads" f32 "$EPOCHS"
  done
done
"$BIN" 10 1 f64 "$EPOCHS"
if [[ "${2:-}" != "--no-torch" ]]; then
  echo "# PyTorch anchor (20 epochs each, 2 threads)"
  python3 "${LSTM_ANCHOR:-/work/shared/anchors/lstm_anchor.py}"
fi
