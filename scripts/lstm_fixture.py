"""Writes PyTorch reference fixtures for seqnet's LSTM (forward outputs, MSE loss, gradients).

Run once from the workspace root:  python3 scripts/lstm_fixture.py
Output: crates/seqnet/tests/data/lstm_torch_<name>_<dtype>.json, read by crates/seqnet/tests/lib/torch.rs.

Weights are stored in PyTorch's own layout (gate order i, f, g, o; weight_ih (4H x F),
weight_hh (4H x H), two bias vectors b_ih and b_hh); the Rust test maps them onto seqnet's layout.
"""
import json
import pathlib

import torch
from torch import nn

OUT = pathlib.Path(__file__).resolve().parent.parent / "crates" / "seqnet" / "tests" / "data"
CASES = {
    # name: (features, steps, hidden, layers, outputs, batch)
    "seq10x1": (1, 10, 8, 1, 12, 4),
    "stacked": (3, 4, 5, 2, 2, 6),
}


class Net(nn.Module):
    def __init__(self, f, h, layers, o):
        super().__init__()
        self.lstm = nn.LSTM(f, h, num_layers=layers, batch_first=True)
        self.out = nn.Linear(h, o)

    def forward(self, x):
        _, (h, _) = self.lstm(x)
        return self.out(h[-1])


def flat(t):
    return [float(v) for v in t.detach().reshape(-1).tolist()]


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    for name, (f, t, h, layers, o, b) in CASES.items():
        for dtype, tag in ((torch.float32, "f32"), (torch.float64, "f64")):
            torch.manual_seed(1234)
            net = Net(f, h, layers, o).to(dtype)
            # Widen the default init so gates leave their linear regime.
            with torch.no_grad():
                for p in net.parameters():
                    p.uniform_(-0.6, 0.6)
            x = torch.randn(b, t, f, dtype=dtype)
            y = torch.randn(b, o, dtype=dtype)
            yhat = net(x)
            loss = nn.functional.mse_loss(yhat, y)
            loss.backward()
            layers_json = []
            for k in range(layers):
                g = lambda n: getattr(net.lstm, f"{n}_l{k}")
                layers_json.append({
                    n: {"value": flat(g(n)), "grad": flat(g(n).grad)}
                    for n in ("weight_ih", "weight_hh", "bias_ih", "bias_hh")
                })
            doc = {
                "generator": f"scripts/lstm_fixture.py, torch {torch.__version__}",
                "dtype": tag,
                "features": f, "steps": t, "hidden": h, "layers": layers, "outputs": o, "batch": b,
                "x": flat(x), "y": flat(y), "yhat": flat(yhat), "loss": float(loss.detach()),
                "lstm": layers_json,
                "head": {n: {"value": flat(getattr(net.out, n)), "grad": flat(getattr(net.out, n).grad)}
                         for n in ("weight", "bias")},
            }
            path = OUT / f"lstm_torch_{name}_{tag}.json"
            path.write_text(json.dumps(doc, indent=None))
            print("wrote", path)


if __name__ == "__main__":
    main()
