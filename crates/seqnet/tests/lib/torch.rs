//! Given identical weights, seqnet's forward outputs, loss and gradients match PyTorch's
//! `nn.LSTM` + `nn.Linear` (fixtures written by scripts/lstm_fixture.py).
//!
//! Mapping PyTorch -> seqnet, for layer k, gate block `p` in PyTorch's order (i, f, g, o) and
//! `s` in ours (f, i, g, o), unit j:
//! * `W[r, s*H + j] = weight_ih[p*H + j, r]` for input rows `r < n_in`,
//!   `W[n_in + r, s*H + j] = weight_hh[p*H + j, r]` for recurrent rows;
//! * `b[s*H + j] = bias_ih[p*H + j] + bias_hh[p*H + j]` (the two biases always enter as a sum, so
//!   PyTorch's gradients of both equal our bias gradient);
//! * head: `W_y[j, o] = weight[o, j]`, `b_y = bias`.

use seqnet::{Float, LstmShape, Network, Workspace};
use serde_json::Value;

/// seqnet gate block -> PyTorch gate block (ours f,i,g,o; theirs i,f,g,o).
const TORCH_BLOCK: [usize; 4] = [1, 0, 2, 3];

fn load(name: &str) -> Value {
    let path = format!("{}/tests/data/{name}.json", env!("CARGO_MANIFEST_DIR"));
    serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap()
}

fn vec_of(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

fn usize_of(doc: &Value, key: &str) -> usize {
    doc[key].as_u64().unwrap() as usize
}

/// Per layer: PyTorch's `bias_ih` and `bias_hh` gradients, reordered to our gate order.
type TorchBiasGrads = Vec<(Vec<f64>, Vec<f64>)>;

/// Builds seqnet-layout parameters from the fixture's `field` ("value" or "grad").
fn to_seqnet_layout(doc: &Value, shape: &LstmShape, field: &str) -> (Vec<f64>, TorchBiasGrads) {
    let h = shape.hidden;
    let mut p = vec![0.0; shape.n_params()];
    let mut torch_bias_grads = Vec::new();
    for l in 0..shape.layers {
        let lj = &doc["lstm"][l];
        let (wih, whh) = (
            vec_of(&lj["weight_ih"][field]),
            vec_of(&lj["weight_hh"][field]),
        );
        let (bih, bhh) = (vec_of(&lj["bias_ih"][field]), vec_of(&lj["bias_hh"][field]));
        let n_in = shape.layer_input(l);
        let off = shape.layer_offset(l);
        for s in 0..4 {
            let pb = TORCH_BLOCK[s];
            for j in 0..h {
                let col = s * h + j;
                let trow = pb * h + j;
                for r in 0..n_in {
                    p[off + r * 4 * h + col] = wih[trow * n_in + r];
                }
                for r in 0..h {
                    p[off + (n_in + r) * 4 * h + col] = whh[trow * h + r];
                }
                p[off + (n_in + h) * 4 * h + col] = if field == "value" {
                    bih[trow] + bhh[trow]
                } else {
                    bih[trow]
                };
            }
        }
        // Reordered to our gate order, for comparing both PyTorch bias gradients.
        let reorder = |b: &[f64]| {
            (0..4 * h)
                .map(|c| b[TORCH_BLOCK[c / h] * h + c % h])
                .collect::<Vec<_>>()
        };
        torch_bias_grads.push((reorder(&bih), reorder(&bhh)));
    }
    let (w, b) = (
        vec_of(&doc["head"]["weight"][field]),
        vec_of(&doc["head"]["bias"][field]),
    );
    let off = shape.head_offset();
    for j in 0..h {
        for o in 0..shape.n_outputs {
            p[off + j * shape.n_outputs + o] = w[o * h + j];
        }
    }
    p[off + h * shape.n_outputs..].copy_from_slice(&b);
    (p, torch_bias_grads)
}

/// max |a - b| / max |b|: error relative to the tensor's scale.
fn rel(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    let scale = b.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
        / scale
}

fn check<T: Float>(name: &str, tol: f64) {
    let doc = load(name);
    let shape = LstmShape::new(
        usize_of(&doc, "features"),
        usize_of(&doc, "steps"),
        usize_of(&doc, "hidden"),
        usize_of(&doc, "layers"),
        usize_of(&doc, "outputs"),
    )
    .unwrap();
    let batch = usize_of(&doc, "batch");
    let (values, _) = to_seqnet_layout(&doc, &shape, "value");
    let (grads, torch_bias) = to_seqnet_layout(&doc, &shape, "grad");
    let net = Network::<T>::from_params(shape, values.iter().map(|&v| T::of(v)).collect()).unwrap();
    // PyTorch's batch_first x is (B, T, F) row-major: exactly seqnet's row layout.
    let x: Vec<T> = vec_of(&doc["x"]).into_iter().map(T::of).collect();
    let y: Vec<T> = vec_of(&doc["y"]).into_iter().map(T::of).collect();
    let mut ws = Workspace::new();
    let yhat: Vec<f64> = net
        .forward(&x, batch, &mut ws)
        .unwrap()
        .iter()
        .map(|v| v.f64())
        .collect();
    assert!(
        rel(&yhat, &vec_of(&doc["yhat"])) < tol,
        "{name}: outputs differ by {}",
        rel(&yhat, &vec_of(&doc["yhat"]))
    );
    let mut g = vec![T::of(0.0); shape.n_params()];
    let loss = net
        .loss_and_gradient(&x, &y, batch, &mut g, &mut ws)
        .unwrap();
    let torch_loss = doc["loss"].as_f64().unwrap();
    assert!(
        (loss - torch_loss).abs() / torch_loss < tol,
        "{name}: loss {loss} vs {torch_loss}"
    );
    let g: Vec<f64> = g.iter().map(|v| v.f64()).collect();
    for l in 0..shape.layers {
        let (off, n_w) = (
            shape.layer_offset(l),
            (shape.layer_input(l) + shape.hidden) * 4 * shape.hidden,
        );
        let e = rel(&g[off..off + n_w], &grads[off..off + n_w]);
        assert!(e < tol, "{name}: layer {l} weight gradient differs by {e}");
        let gb = &g[off + n_w..off + n_w + 4 * shape.hidden];
        for tb in [&torch_bias[l].0, &torch_bias[l].1] {
            assert!(
                rel(gb, tb) < tol,
                "{name}: layer {l} bias gradient differs by {}",
                rel(gb, tb)
            );
        }
    }
    let off = shape.head_offset();
    assert!(
        rel(&g[off..], &grads[off..]) < tol,
        "{name}: head gradient differs by {}",
        rel(&g[off..], &grads[off..])
    );
}

// f32: both sides round each product and sum to f32 (eps 6e-8) in different orders and with
// different exp/tanh implementations; over ~10 steps of 10-term dot products this stays well
// inside the brief's 1e-5 relative bound.
#[test]
fn matches_torch_f32_seq10x1() {
    check::<f32>("lstm_torch_seq10x1_f32", 1e-5);
}

#[test]
fn matches_torch_f32_stacked() {
    check::<f32>("lstm_torch_stacked_f32", 1e-5);
}

// f64: same argument with eps 1.1e-16; 1e-12 leaves four orders of magnitude for accumulation.
#[test]
fn matches_torch_f64_seq10x1() {
    check::<f64>("lstm_torch_seq10x1_f64", 1e-12);
}

#[test]
fn matches_torch_f64_stacked() {
    check::<f64>("lstm_torch_stacked_f64", 1e-12);
}
