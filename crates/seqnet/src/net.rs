//! Network shape, flat parameter layout, the batched forward pass (Eq. 28) and hand-written
//! backpropagation through time.
//!
//! # Layout
//! All parameters live in one flat vector (so optimisers, clipping, finite-difference checks and
//! serialisation treat them uniformly). For layer `l` with `n_in` inputs per step (`n_features` for
//! the first layer, `hidden` above it) the block is
//!
//! * `W_l`: `(n_in + hidden) x 4 hidden`, row-major. Rows `0..n_in` multiply the step input `x_t`,
//!   rows `n_in..` multiply the previous hidden state `h_{t-1}`: the concatenation
//!   `[x_t, h_{t-1}] W_l` is Eq. 28's `W_* [h_{t-1}, x_t]` for all four gates at once.
//! * `b_l`: `4 hidden`.
//!
//! The four column blocks of width `hidden` are the gates in the paper's order:
//! **forget, input, candidate, output** (`f, i, C~, o`). (PyTorch orders them `i, f, g, o`.)
//! The dense head follows: `W_y` (`hidden x n_outputs`, row-major) and `b_y` (`n_outputs`).
//!
//! # Kernels
//! One GEMM per layer and step computes all gates of the whole batch:
//! `Z_t (B x 4H) = [x_t, h_{t-1}] (B x (F+H)) * W ((F+H) x 4H)`. The backward pass needs per step
//! `dh_{t-1} = dZ_t W_h^T` (and `dx_t = dZ_t W_x^T` below the top layer), and after the time loop a
//! single `(F+H) x (T B) x 4H` GEMM accumulates the weight gradient over all steps.

use crate::error::SeqError;
use crate::float::Float;
use crate::gemm::{gemm, view, view_mut};
use faer::{Accum, Par};
use numerics::random::standard_normal;
use rand::{RngExt, SeedableRng, rngs::StdRng};
use serde::{Deserialize, Serialize};

/// Shape of a stacked LSTM with a dense head on the last hidden state.
///
/// A sample's `n_inputs = steps * n_features` values are fed as `steps` time steps of
/// `n_features` consecutive values each.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct LstmShape {
    /// Values fed per time step (`F`).
    pub n_features: usize,
    /// Sequence length (`T`).
    pub steps: usize,
    /// Hidden units per layer (`H`).
    pub hidden: usize,
    /// Number of stacked LSTM layers (`L`).
    pub layers: usize,
    /// Outputs of the dense head.
    pub n_outputs: usize,
}

impl LstmShape {
    /// Validated constructor: every size must be positive.
    ///
    /// ```
    /// let s = seqnet::LstmShape::new(1, 10, 64, 1, 12).unwrap();
    /// assert_eq!(s.n_inputs(), 10);
    /// assert!(seqnet::LstmShape::new(1, 0, 64, 1, 12).is_err());
    /// ```
    pub fn new(
        n_features: usize,
        steps: usize,
        hidden: usize,
        layers: usize,
        n_outputs: usize,
    ) -> Result<Self, SeqError> {
        for (name, v) in [
            ("n_features", n_features),
            ("steps", steps),
            ("hidden", hidden),
            ("layers", layers),
            ("n_outputs", n_outputs),
        ] {
            if v == 0 {
                return Err(SeqError::InvalidParameter {
                    name,
                    reason: "must be at least 1".into(),
                });
            }
        }
        Ok(Self {
            n_features,
            steps,
            hidden,
            layers,
            n_outputs,
        })
    }

    /// Inputs per sample, `steps * n_features`.
    ///
    /// ```
    /// assert_eq!(seqnet::LstmShape::new(2, 5, 8, 1, 3).unwrap().n_inputs(), 10);
    /// ```
    pub fn n_inputs(&self) -> usize {
        self.steps * self.n_features
    }

    /// Inputs per step of layer `l` (`n_features` for layer 0, `hidden` above).
    ///
    /// ```
    /// let s = seqnet::LstmShape::new(2, 5, 8, 2, 3).unwrap();
    /// assert_eq!((s.layer_input(0), s.layer_input(1)), (2, 8));
    /// ```
    pub fn layer_input(&self, l: usize) -> usize {
        if l == 0 { self.n_features } else { self.hidden }
    }

    fn layer_len(&self, l: usize) -> usize {
        (self.layer_input(l) + self.hidden) * 4 * self.hidden + 4 * self.hidden
    }

    /// Offset of layer `l`'s weight block in the flat parameter vector.
    ///
    /// ```
    /// let s = seqnet::LstmShape::new(1, 3, 2, 2, 1).unwrap();
    /// assert_eq!(s.layer_offset(0), 0);
    /// assert_eq!(s.layer_offset(1), (1 + 2) * 8 + 8);
    /// ```
    pub fn layer_offset(&self, l: usize) -> usize {
        (0..l).map(|k| self.layer_len(k)).sum()
    }

    /// Offset of the head weights `W_y` in the flat parameter vector.
    ///
    /// ```
    /// let s = seqnet::LstmShape::new(1, 3, 2, 1, 1).unwrap();
    /// assert_eq!(s.head_offset(), (1 + 2) * 8 + 8);
    /// ```
    pub fn head_offset(&self) -> usize {
        self.layer_offset(self.layers)
    }

    /// Total number of trainable parameters.
    ///
    /// ```
    /// // PyTorch's nn.LSTM(1, 64) + Linear(64, 12) has 4*64*(1+64) + 2*4*64 + 64*12 + 12 weights;
    /// // we have one bias vector per layer instead of two, so 256 fewer.
    /// let s = seqnet::LstmShape::new(1, 10, 64, 1, 12).unwrap();
    /// assert_eq!(s.n_params(), 4 * 64 * 65 + 4 * 64 + 64 * 12 + 12);
    /// ```
    pub fn n_params(&self) -> usize {
        self.head_offset() + self.hidden * self.n_outputs + self.n_outputs
    }
}

/// Reusable per-batch buffers of the forward and backward passes.
///
/// Create one per thread and pass it to every call; buffers only grow, so a training loop does not
/// allocate after the first mini-batch.
#[derive(Debug, Clone)]
pub struct Workspace<T> {
    batch: usize,
    par: Par,
    /// Runtime-detected SIMD level for the element-wise gate kernels.
    arch: pulp::Arch,
    /// Per layer: `[x_t, h_{t-1}]` for all steps, `T x B x (n_in + H)`.
    xh: Vec<Vec<T>>,
    /// Per layer: activated gates `f, i, C~, o`, `T x B x 4H`.
    gates: Vec<Vec<T>>,
    /// Per layer: cell states `C_t`, `T x B x H`.
    cells: Vec<Vec<T>>,
    /// Per layer: `tanh(C_t)`, `T x B x H`.
    tanh_c: Vec<Vec<T>>,
    /// Per layer: hidden states `h_t`, `T x B x H`.
    hs: Vec<Vec<T>>,
    out: Vec<T>,
    dout: Vec<T>,
    dz: Vec<T>,
    dc: Vec<T>,
    dh_rec: Vec<T>,
    dh_above: Vec<T>,
    dh_below: Vec<T>,
    /// `B x H` zeros: the cell state before the first step.
    c_zero: Vec<T>,
}

impl<T: Float> Default for Workspace<T> {
    fn default() -> Self {
        Self::new()
    }
}

impl<T: Float> Workspace<T> {
    /// An empty workspace using sequential GEMMs.
    ///
    /// ```
    /// let ws = seqnet::Workspace::<f32>::new();
    /// # let _ = ws;
    /// ```
    pub fn new() -> Self {
        Self::with_par(Par::Seq)
    }

    /// An empty workspace whose GEMMs run on `threads` rayon threads (`0` or `1`: sequential,
    /// like [`Workspace::new`]); at this crate's small shapes sequential GEMMs are usually
    /// faster, see docs/benchmarks.md. (Mini-batch parallelism is the separate
    /// [`LstmSettings::threads`](crate::LstmSettings::threads).)
    ///
    /// ```
    /// let ws = seqnet::Workspace::<f64>::with_gemm_threads(2);
    /// # let _ = ws;
    /// ```
    pub fn with_gemm_threads(threads: usize) -> Self {
        Self::with_par(if threads <= 1 {
            Par::Seq
        } else {
            Par::rayon(threads)
        })
    }

    fn with_par(par: Par) -> Self {
        Self {
            batch: 0,
            par,
            arch: pulp::Arch::new(),
            xh: Vec::new(),
            gates: Vec::new(),
            cells: Vec::new(),
            tanh_c: Vec::new(),
            hs: Vec::new(),
            out: Vec::new(),
            dout: Vec::new(),
            dz: Vec::new(),
            dc: Vec::new(),
            dh_rec: Vec::new(),
            dh_above: Vec::new(),
            dh_below: Vec::new(),
            c_zero: Vec::new(),
        }
    }

    fn prepare(&mut self, s: &LstmShape, b: usize) {
        let (t, h) = (s.steps, s.hidden);
        let zero = T::of(0.0);
        self.batch = b;
        let per_layer = |v: &mut Vec<Vec<T>>, width: &dyn Fn(usize) -> usize| {
            v.resize_with(s.layers, Vec::new);
            for (l, buf) in v.iter_mut().enumerate() {
                buf.resize(t * b * width(l), zero);
            }
        };
        per_layer(&mut self.xh, &|l| s.layer_input(l) + h);
        per_layer(&mut self.gates, &|_| 4 * h);
        per_layer(&mut self.cells, &|_| h);
        per_layer(&mut self.tanh_c, &|_| h);
        per_layer(&mut self.hs, &|_| h);
        self.out.resize(b * s.n_outputs, zero);
        self.dout.resize(b * s.n_outputs, zero);
        self.dz.resize(t * b * 4 * h, zero);
        self.dc.resize(b * h, zero);
        self.dh_rec.resize(b * h, zero);
        self.dh_above.resize(t * b * h, zero);
        self.dh_below.resize(t * b * h, zero);
        self.c_zero.resize(b * h, zero);
    }
}

/// A stacked LSTM (Eq. 28) with a dense head, generic over the scalar type.
///
/// This is the low-level, allocation-free engine behind [`crate::LstmRegressor`]: inputs and
/// targets are raw row-major slices in standardised units, and gradients come from hand-written
/// backpropagation through time.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(bound = "")]
pub struct Network<T: Float> {
    shape: LstmShape,
    params: Vec<T>,
}

impl<T: Float> Network<T> {
    /// A freshly initialised network: Xavier-uniform input and head weights, orthogonal recurrent
    /// weights (one orthogonal `H x H` block per gate), zero biases except the forget gate's,
    /// which start at 1 so early training does not forget by default.
    ///
    /// ```
    /// let s = seqnet::LstmShape::new(1, 4, 8, 1, 2).unwrap();
    /// let a = seqnet::Network::<f64>::init(s, 7);
    /// assert_eq!(a, seqnet::Network::<f64>::init(s, 7)); // same seed -> same weights
    /// ```
    pub fn init(shape: LstmShape, seed: u64) -> Self {
        let mut rng = StdRng::seed_from_u64(seed);
        let h = shape.hidden;
        let mut p = vec![T::of(0.0); shape.n_params()];
        for l in 0..shape.layers {
            let n_in = shape.layer_input(l);
            let off = shape.layer_offset(l);
            let w = &mut p[off..off + (n_in + h) * 4 * h];
            let a = (6.0 / (n_in + 4 * h) as f64).sqrt();
            for v in &mut w[..n_in * 4 * h] {
                *v = T::of(rng.random_range(-a..a));
            }
            for gate in 0..4 {
                let q = orthogonal(h, &mut rng);
                for r in 0..h {
                    for c in 0..h {
                        w[(n_in + r) * 4 * h + gate * h + c] = T::of(q[r * h + c]);
                    }
                }
            }
            let b = &mut p[off + (n_in + h) * 4 * h..off + shape.layer_len(l)];
            b[..h].fill(T::of(1.0)); // forget block
        }
        let off = shape.head_offset();
        let a = (6.0 / (h + shape.n_outputs) as f64).sqrt();
        for v in &mut p[off..off + h * shape.n_outputs] {
            *v = T::of(rng.random_range(-a..a));
        }
        Self { shape, params: p }
    }

    /// Wraps an explicit parameter vector (layout in the module docs).
    ///
    /// ```
    /// let s = seqnet::LstmShape::new(1, 2, 3, 1, 1).unwrap();
    /// let net = seqnet::Network::from_params(s, vec![0.0f64; s.n_params()]).unwrap();
    /// assert!(seqnet::Network::from_params(s, vec![0.0f64; 3]).is_err());
    /// # let _ = net;
    /// ```
    pub fn from_params(shape: LstmShape, params: Vec<T>) -> Result<Self, SeqError> {
        if params.len() != shape.n_params() {
            return Err(SeqError::Shape {
                what: "params",
                expected: format!("{} values for {shape:?}", shape.n_params()),
                found: format!("{} values", params.len()),
            });
        }
        Ok(Self { shape, params })
    }

    /// The network's shape.
    ///
    /// ```
    /// let s = seqnet::LstmShape::new(1, 2, 3, 1, 1).unwrap();
    /// assert_eq!(seqnet::Network::<f32>::init(s, 0).shape(), &s);
    /// ```
    pub fn shape(&self) -> &LstmShape {
        &self.shape
    }

    /// The flat parameter vector.
    ///
    /// ```
    /// let s = seqnet::LstmShape::new(1, 2, 3, 1, 1).unwrap();
    /// assert_eq!(seqnet::Network::<f32>::init(s, 0).params().len(), s.n_params());
    /// ```
    pub fn params(&self) -> &[T] {
        &self.params
    }

    /// Mutable access to the flat parameter vector (its length cannot change).
    ///
    /// ```
    /// let s = seqnet::LstmShape::new(1, 2, 3, 1, 1).unwrap();
    /// let mut net = seqnet::Network::<f64>::init(s, 0);
    /// net.params_mut()[0] = 0.5;
    /// assert_eq!(net.params()[0], 0.5);
    /// ```
    pub fn params_mut(&mut self) -> &mut [T] {
        &mut self.params
    }

    fn check_batch(&self, x: &[T], batch: usize) -> Result<(), SeqError> {
        if batch == 0 || x.len() != batch * self.shape.n_inputs() {
            return Err(SeqError::Shape {
                what: "x",
                expected: format!(
                    "a non-empty batch of rows of {} inputs",
                    self.shape.n_inputs()
                ),
                found: format!("{} values for batch {batch}", x.len()),
            });
        }
        Ok(())
    }

    /// Forward pass for a row-major `batch x n_inputs` input; returns the `batch x n_outputs`
    /// outputs (row-major, borrowed from the workspace).
    ///
    /// ```
    /// let s = seqnet::LstmShape::new(2, 3, 4, 2, 5).unwrap();
    /// let net = seqnet::Network::<f64>::init(s, 1);
    /// let mut ws = seqnet::Workspace::new();
    /// let y = net.forward(&vec![0.1; 2 * 6], 2, &mut ws).unwrap();
    /// assert_eq!(y.len(), 2 * 5);
    /// ```
    pub fn forward<'w>(
        &self,
        x: &[T],
        batch: usize,
        ws: &'w mut Workspace<T>,
    ) -> Result<&'w [T], SeqError> {
        self.check_batch(x, batch)?;
        self.forward_unchecked(x, batch, ws);
        Ok(&ws.out[..batch * self.shape.n_outputs])
    }

    /// Mean squared error `sum((yhat - y)^2) / (batch * n_outputs)` (PyTorch's `mse_loss`).
    ///
    /// ```
    /// let s = seqnet::LstmShape::new(1, 2, 3, 1, 1).unwrap();
    /// let net = seqnet::Network::<f64>::init(s, 0);
    /// let mut ws = seqnet::Workspace::new();
    /// let l = net.loss(&[0.0, 1.0], &[0.5], 1, &mut ws).unwrap();
    /// assert!(l >= 0.0);
    /// ```
    pub fn loss(
        &self,
        x: &[T],
        y: &[T],
        batch: usize,
        ws: &mut Workspace<T>,
    ) -> Result<f64, SeqError> {
        self.check_batch(x, batch)?;
        self.check_targets(y, batch)?;
        self.forward_unchecked(x, batch, ws);
        let n = (batch * self.shape.n_outputs) as f64;
        Ok(ws.out[..y.len()]
            .iter()
            .zip(y)
            .map(|(a, b)| (a.f64() - b.f64()).powi(2))
            .sum::<f64>()
            / n)
    }

    fn check_targets(&self, y: &[T], batch: usize) -> Result<(), SeqError> {
        if y.len() != batch * self.shape.n_outputs {
            return Err(SeqError::Shape {
                what: "y",
                expected: format!("{batch} rows of {} outputs", self.shape.n_outputs),
                found: format!("{} values", y.len()),
            });
        }
        Ok(())
    }

    /// Mean squared error and its exact gradient (written into `grad`, same layout as
    /// [`Network::params`]) by backpropagation through time.
    ///
    /// ```
    /// let s = seqnet::LstmShape::new(1, 2, 3, 1, 1).unwrap();
    /// let net = seqnet::Network::<f64>::init(s, 0);
    /// let mut g = vec![0.0; s.n_params()];
    /// let mut ws = seqnet::Workspace::new();
    /// let l = net.loss_and_gradient(&[0.0, 1.0], &[0.5], 1, &mut g, &mut ws).unwrap();
    /// assert!(l >= 0.0 && g.iter().any(|v| *v != 0.0));
    /// ```
    pub fn loss_and_gradient(
        &self,
        x: &[T],
        y: &[T],
        batch: usize,
        grad: &mut [T],
        ws: &mut Workspace<T>,
    ) -> Result<f64, SeqError> {
        self.check_batch(x, batch)?;
        self.check_targets(y, batch)?;
        if grad.len() != self.params.len() {
            return Err(SeqError::Shape {
                what: "grad",
                expected: format!("{} values", self.params.len()),
                found: format!("{} values", grad.len()),
            });
        }
        let n = batch * self.shape.n_outputs;
        let sse = self.sse_and_gradient(x, y, batch, 1.0 / n as f64, grad, ws);
        Ok(sse / n as f64)
    }

    /// Sum of squared errors, and `grad = scale * d(sse)/d(params)` (overwritten). The scale lets
    /// batch shards compute their share of a mean-loss gradient independently.
    pub(crate) fn sse_and_gradient(
        &self,
        x: &[T],
        y: &[T],
        batch: usize,
        scale: f64,
        grad: &mut [T],
        ws: &mut Workspace<T>,
    ) -> f64 {
        self.forward_unchecked(x, batch, ws);
        self.backward(y, batch, scale, grad, ws)
    }

    fn forward_unchecked(&self, x: &[T], b: usize, ws: &mut Workspace<T>) {
        ws.prepare(&self.shape, b);
        self.load_inputs(x, b, ws);
        for l in 0..self.shape.layers {
            self.forward_layer(l, b, ws);
        }
        self.forward_head(b, ws);
    }

    /// Layer-0 inputs: sample row `r`, step `t` is `x[r, t*F .. (t+1)*F]`.
    fn load_inputs(&self, x: &[T], b: usize, ws: &mut Workspace<T>) {
        let s = self.shape;
        let f = s.n_features;
        let row = f + s.hidden;
        let xh = &mut ws.xh[0];
        for t in 0..s.steps {
            for r in 0..b {
                let dst = (t * b + r) * row;
                xh[dst..dst + f].copy_from_slice(&x[r * s.n_inputs() + t * f..][..f]);
            }
        }
    }

    /// All steps of layer `l` (Eq. 28): per step, one GEMM for the four gates of the batch,
    /// then the element-wise cell; the hidden state feeds the next step and the layer above.
    fn forward_layer(&self, l: usize, b: usize, ws: &mut Workspace<T>) {
        let s = self.shape;
        let (tn, h) = (s.steps, s.hidden);
        let n_in = s.layer_input(l);
        let row = n_in + h;
        let off = s.layer_offset(l);
        let w = &self.params[off..off + row * 4 * h];
        let bias = &self.params[off + row * 4 * h..off + s.layer_len(l)];
        let par = ws.par;
        // h_{-1} = 0
        for r in 0..b {
            ws.xh[l][r * row + n_in..(r + 1) * row].fill(T::of(0.0));
        }
        for t in 0..tn {
            let z = &mut ws.gates[l][t * b * 4 * h..(t + 1) * b * 4 * h];
            let xh_t = &ws.xh[l][t * b * row..(t + 1) * b * row];
            gemm(
                view_mut(z, b, 4 * h),
                Accum::Replace,
                view(xh_t, b, row),
                view(w, row, 4 * h),
                par,
            );
            let (c_done, c_rest) = ws.cells[l].split_at_mut(t * b * h);
            let c_prev = if t == 0 {
                &ws.c_zero[..]
            } else {
                &c_done[(t - 1) * b * h..]
            };
            let tanh_c = &mut ws.tanh_c[l][t * b * h..(t + 1) * b * h];
            let h_t = &mut ws.hs[l][t * b * h..(t + 1) * b * h];
            ws.arch.dispatch(CellForward {
                z,
                bias,
                c_prev,
                c: &mut c_rest[..b * h],
                tanh_c,
                h_out: h_t,
                h,
            });
            pass_hidden(ws, &s, l, t, b);
        }
    }

    /// Dense head on the top layer's last hidden state.
    fn forward_head(&self, b: usize, ws: &mut Workspace<T>) {
        let s = self.shape;
        let (tn, h, o) = (s.steps, s.hidden, s.n_outputs);
        let off = s.head_offset();
        let (wy, by) = (&self.params[off..off + h * o], &self.params[off + h * o..]);
        let h_last = &ws.hs[s.layers - 1][(tn - 1) * b * h..tn * b * h];
        let out = &mut ws.out[..b * o];
        for r in 0..b {
            out[r * o..(r + 1) * o].copy_from_slice(by);
        }
        gemm(
            view_mut(out, b, o),
            Accum::Add,
            view(h_last, b, h),
            view(wy, h, o),
            ws.par,
        );
    }

    fn backward(
        &self,
        y: &[T],
        b: usize,
        scale: f64,
        grad: &mut [T],
        ws: &mut Workspace<T>,
    ) -> f64 {
        let sse = self.head_backward(y, b, scale, grad, ws);
        for l in (0..self.shape.layers).rev() {
            self.layer_backward(l, b, grad, ws);
            std::mem::swap(&mut ws.dh_above, &mut ws.dh_below);
        }
        sse
    }

    /// Output error `d(scale * sse)/d(yhat) = 2 scale (yhat - y)` into `ws.dout`, the head's
    /// weight and bias gradients, and `dL/dh` of the top layer's last step into `ws.dh_above`
    /// (zero at the other steps). Returns the sum of squared errors.
    fn head_backward(
        &self,
        y: &[T],
        b: usize,
        scale: f64,
        grad: &mut [T],
        ws: &mut Workspace<T>,
    ) -> f64 {
        let s = self.shape;
        let (tn, h, o) = (s.steps, s.hidden, s.n_outputs);
        let par = ws.par;
        let mut sse = 0.0;
        let two_scale = T::of(2.0 * scale);
        for ((d, &yh), &yt) in ws.dout[..b * o].iter_mut().zip(&ws.out[..b * o]).zip(y) {
            let e = yh - yt;
            sse += e.f64() * e.f64();
            *d = two_scale * e;
        }
        let off = s.head_offset();
        let wy = &self.params[off..off + h * o];
        let h_last = &ws.hs[s.layers - 1][(tn - 1) * b * h..tn * b * h];
        {
            let (gw, gb) = grad[off..].split_at_mut(h * o);
            gemm(
                view_mut(gw, h, o),
                Accum::Replace,
                view(h_last, b, h).transpose(),
                view(&ws.dout, b, o),
                par,
            );
            column_sums(&ws.dout[..b * o], o, gb);
        }
        ws.dh_above[..tn * b * h].fill(T::of(0.0));
        gemm(
            view_mut(&mut ws.dh_above[(tn - 1) * b * h..], b, h),
            Accum::Replace,
            view(&ws.dout, b, o),
            view(wy, h, o).transpose(),
            par,
        );
        sse
    }

    /// Backpropagation through all steps of layer `l` (last step first) with `dL/dh` from
    /// above in `ws.dh_above`; writes the layer's weight and bias gradients and, below the
    /// first layer, `dL/dh` of the layer beneath into `ws.dh_below`.
    fn layer_backward(&self, l: usize, b: usize, grad: &mut [T], ws: &mut Workspace<T>) {
        let s = self.shape;
        let (tn, h) = (s.steps, s.hidden);
        let row = s.layer_input(l) + h;
        let off = s.layer_offset(l);
        let zero = T::of(0.0);
        ws.dc[..b * h].fill(zero);
        ws.dh_rec[..b * h].fill(zero);
        for t in (0..tn).rev() {
            self.step_backward(l, t, b, ws);
        }
        let (gw, gb) = grad[off..off + s.layer_len(l)].split_at_mut(row * 4 * h);
        gemm(
            view_mut(gw, row, 4 * h),
            Accum::Replace,
            view(&ws.xh[l], tn * b, row).transpose(),
            view(&ws.dz, tn * b, 4 * h),
            ws.par,
        );
        column_sums(&ws.dz[..tn * b * 4 * h], 4 * h, gb);
    }

    /// One step `t` of layer `l` backwards: the gate gradients `dZ_t` (into `ws.dz`), the
    /// cell-state gradient carried to step `t - 1` (`ws.dc`), the recurrent `dh_{t-1} = dZ_t
    /// W_h^T` (`ws.dh_rec`) and, below the first layer, `dx_t = dZ_t W_x^T` (`ws.dh_below`).
    fn step_backward(&self, l: usize, t: usize, b: usize, ws: &mut Workspace<T>) {
        let s = self.shape;
        let h = s.hidden;
        let n_in = s.layer_input(l);
        let row = n_in + h;
        let off = s.layer_offset(l);
        let w = view(&self.params[off..off + row * 4 * h], row, 4 * h);
        let par = ws.par;
        let span = t * b * h..(t + 1) * b * h;
        let c_prev = if t == 0 {
            &ws.c_zero[..]
        } else {
            &ws.cells[l][(t - 1) * b * h..t * b * h]
        };
        let dz_t = &mut ws.dz[t * b * 4 * h..(t + 1) * b * 4 * h];
        let gates = &ws.gates[l][t * b * 4 * h..(t + 1) * b * 4 * h];
        let (tanh_c, above) = (&ws.tanh_c[l][span.clone()], &ws.dh_above[span.clone()]);
        let (rec, dc) = (&ws.dh_rec[..b * h], &mut ws.dc[..b * h]);
        ws.arch.dispatch(CellBackward {
            gates,
            c_prev,
            tanh_c,
            dh_above: above,
            dh_rec: rec,
            dc,
            dz: dz_t,
            h,
        });
        let dz_t = view(dz_t, b, 4 * h);
        if t > 0 {
            let w_h = w.subrows(n_in, h).transpose();
            gemm(
                view_mut(&mut ws.dh_rec, b, h),
                Accum::Replace,
                dz_t,
                w_h,
                par,
            );
        }
        if l > 0 {
            let w_x = w.subrows(0, n_in).transpose();
            gemm(
                view_mut(&mut ws.dh_below[span], b, h),
                Accum::Replace,
                dz_t,
                w_x,
                par,
            );
        }
    }
}

/// Copies step `t`'s hidden state of layer `l` into the recurrent part of step `t + 1`'s input
/// rows and into the input part of layer `l + 1`'s step-`t` rows.
fn pass_hidden<T: Float>(ws: &mut Workspace<T>, s: &LstmShape, l: usize, t: usize, b: usize) {
    let (tn, h) = (s.steps, s.hidden);
    let n_in = s.layer_input(l);
    let row = n_in + h;
    let h_t = &ws.hs[l][t * b * h..(t + 1) * b * h];
    if t + 1 < tn {
        let xh_next = &mut ws.xh[l][(t + 1) * b * row..(t + 2) * b * row];
        for r in 0..b {
            xh_next[r * row + n_in..(r + 1) * row].copy_from_slice(&h_t[r * h..(r + 1) * h]);
        }
    }
    if l + 1 < s.layers {
        let up = &mut ws.xh[l + 1][t * b * 2 * h..(t + 1) * b * 2 * h];
        for r in 0..b {
            up[r * 2 * h..r * 2 * h + h].copy_from_slice(&h_t[r * h..(r + 1) * h]);
        }
    }
}

/// Arguments of [`cell_forward`], run through pulp's runtime SIMD dispatch so the element-wise
/// loops are compiled for AVX2/FMA (or better) when the CPU has it.
struct CellForward<'a, T> {
    z: &'a mut [T],
    bias: &'a [T],
    c_prev: &'a [T],
    c: &'a mut [T],
    tanh_c: &'a mut [T],
    h_out: &'a mut [T],
    h: usize,
}

impl<T: Float> pulp::WithSimd for CellForward<'_, T> {
    type Output = ();
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) {
        cell_forward(
            self.z,
            self.bias,
            self.c_prev,
            self.c,
            self.tanh_c,
            self.h_out,
            self.h,
        );
    }
}

/// Arguments of [`cell_backward`] for pulp's dispatch.
struct CellBackward<'a, T> {
    gates: &'a [T],
    c_prev: &'a [T],
    tanh_c: &'a [T],
    dh_above: &'a [T],
    dh_rec: &'a [T],
    dc: &'a mut [T],
    dz: &'a mut [T],
    h: usize,
}

impl<T: Float> pulp::WithSimd for CellBackward<'_, T> {
    type Output = ();
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) {
        cell_backward(self);
    }
}

/// Gate activations, cell and hidden state for one step of one layer (Eq. 28, steps 1-4).
/// `z` holds the raw `[x_t, h_{t-1}] W` for `B` rows of `4H`; it is overwritten with the activated
/// gates `f, i, C~, o`, which the backward pass reuses. Each loop runs over a contiguous slice with
/// a branch-free body so it vectorises.
#[inline(always)]
fn cell_forward<T: Float>(
    z: &mut [T],
    bias: &[T],
    c_prev: &[T],
    c: &mut [T],
    tanh_c: &mut [T],
    h_out: &mut [T],
    h: usize,
) {
    for (r, zr) in z.chunks_exact_mut(4 * h).enumerate() {
        for (v, b) in zr.iter_mut().zip(bias) {
            *v += *b;
        }
        let (fi, rest) = zr.split_at_mut(2 * h);
        let (g, o) = rest.split_at_mut(h);
        sigmoid_slice(fi);
        sigmoid_slice(o);
        tanh_slice(g);
        let (f, i) = fi.split_at(h);
        let (f, i, g, o) = (&f[..h], &i[..h], &g[..h], &o[..h]);
        let span = r * h..(r + 1) * h;
        let (cr, pr) = (&mut c[span.clone()], &c_prev[span.clone()]);
        for j in 0..h {
            cr[j] = f[j] * pr[j] + i[j] * g[j];
        }
        let tr = &mut tanh_c[span.clone()];
        tr.copy_from_slice(cr);
        tanh_slice(tr);
        let hr = &mut h_out[span];
        for j in 0..h {
            hr[j] = o[j] * tr[j];
        }
    }
}

/// In-place logistic sigmoid of a slice (a separate loop so it vectorises).
#[inline(always)]
fn sigmoid_slice<T: Float>(xs: &mut [T]) {
    for v in xs {
        *v = v.sigmoid();
    }
}

/// In-place hyperbolic tangent of a slice.
#[inline(always)]
fn tanh_slice<T: Float>(xs: &mut [T]) {
    for v in xs {
        *v = v.tanh_fast();
    }
}

/// Backward through one LSTM step. `dh_rec` holds dL/dh_t coming from step t+1 on entry and is
/// left for the caller to overwrite; `dc` carries dL/dC_t in and dL/dC_{t-1} out. Writes
/// dL/dZ_t (pre-activation gate gradients) into `dz`.
#[inline(always)]
fn cell_backward<T: Float>(args: CellBackward<'_, T>) {
    let CellBackward {
        gates,
        c_prev,
        tanh_c,
        dh_above,
        dh_rec,
        dc,
        dz,
        h,
    } = args;
    let one = T::of(1.0);
    for (r, (gr, dzr)) in gates
        .chunks_exact(4 * h)
        .zip(dz.chunks_exact_mut(4 * h))
        .enumerate()
    {
        let (dzf, rest) = dzr.split_at_mut(h);
        let (dzi, rest) = rest.split_at_mut(h);
        let (dzg, dzo) = rest.split_at_mut(h);
        let (f, rest) = gr.split_at(h);
        let (i, rest) = rest.split_at(h);
        let (g, o) = rest.split_at(h);
        // Re-slicing to exactly h lets the compiler drop bounds checks and vectorise.
        let (f, i, g, o) = (&f[..h], &i[..h], &g[..h], &o[..h]);
        let (dzf, dzi, dzg, dzo) = (&mut dzf[..h], &mut dzi[..h], &mut dzg[..h], &mut dzo[..h]);
        let span = r * h..(r + 1) * h;
        let (tc, cp, above) = (
            &tanh_c[span.clone()],
            &c_prev[span.clone()],
            &dh_above[span.clone()],
        );
        let (rec, dcr) = (&dh_rec[span.clone()], &mut dc[span]);
        for j in 0..h {
            let dh = above[j] + rec[j];
            let dcell = dcr[j] + dh * o[j] * (one - tc[j] * tc[j]);
            dzo[j] = dh * tc[j] * o[j] * (one - o[j]);
            dzf[j] = dcell * cp[j] * f[j] * (one - f[j]);
            dzi[j] = dcell * g[j] * i[j] * (one - i[j]);
            dzg[j] = dcell * i[j] * (one - g[j] * g[j]);
            dcr[j] = dcell * f[j];
        }
    }
}

/// `out[j] = sum_r m[r, j]` for a row-major matrix with `cols` columns.
fn column_sums<T: Float>(m: &[T], cols: usize, out: &mut [T]) {
    out.fill(T::of(0.0));
    for row in m.chunks_exact(cols) {
        for (o, &v) in out.iter_mut().zip(row) {
            *o += v;
        }
    }
}

/// A random `n x n` orthogonal matrix (row-major): modified Gram-Schmidt on a Gaussian matrix,
/// rows sign-normalised as in QR with a positive diagonal of R.
fn orthogonal(n: usize, rng: &mut StdRng) -> Vec<f64> {
    let mut q: Vec<f64> = (0..n * n).map(|_| standard_normal(rng)).collect();
    for i in 0..n {
        for k in 0..i {
            let d: f64 = (0..n).map(|c| q[i * n + c] * q[k * n + c]).sum();
            for c in 0..n {
                q[i * n + c] -= d * q[k * n + c];
            }
        }
        let norm = (0..n).map(|c| q[i * n + c].powi(2)).sum::<f64>().sqrt();
        // A Gaussian matrix is singular with probability zero; guard anyway.
        let inv = if norm > 1e-12 { 1.0 / norm } else { 0.0 };
        for c in 0..n {
            q[i * n + c] *= inv;
        }
    }
    q
}
