//! The LQR baseline's per-step work: the Kalman filter's predict and update, then the control
//! law, for one env (the design: [`crate::control::lqr`]).
//!
//! ```text
//! z- = F z + G u_sent                     (predict with the command actually sent; z- = 0 at an episode's start)
//! z  = z- + L (y_m - y*_m - H z-)          (update with the observation)
//! u  = clip(-K dx + K_ff (w_y, w_z, r_y, r_z), -1, 1)
//! ```
//!
//! Every sum runs over its index in ascending order with separate multiplications and additions
//! (the matrices are stored transposed so that each term is a scaled column added to the
//! outputs, which the compiler vectorizes across outputs without reordering any one sum): a
//! row's result depends on nothing but its own inputs, the same bits on every CPU, with any
//! batch size and any number of threads. On x86-64 with AVX the same loops run four lanes wide
//! instead of two, which changes no bit (separate multiplications and additions, each output's
//! order unchanged). A batch's rows are predicted in blocks that share each read of `F`
//! ([`LqrFilter::step_rows`]). No allocation per step: each env's [`FilterState`] holds its
//! scratch space.

use crate::control::lqr::{LqrDesign, EXTRA_STATES, MEASURED, MEASURED_DIM};
use crate::control::matrix::Matrix;
use crate::error::{Result, SimError};
use crate::task::linearize::WIND_DIM;
use crate::task::observation::{ACT_DIM, OBS_DIM};

/// The matrices of one design in the layout the step reads (see the module docs).
#[derive(Debug, Clone)]
pub struct LqrFilter {
    n: usize,
    /// `F^T` (nz x nz): row j is column j of `F`.
    ft: Matrix,
    /// `G^T` (4 x nz).
    gt: Matrix,
    /// `H^T` (nz x 24).
    ht: Matrix,
    /// `L^T` (24 x nz).
    lt: Matrix,
    /// `K^T` (n x 4).
    kt: Matrix,
    /// `K_ff^T` (4 x 4).
    kfft: Matrix,
    y_trim: [f64; MEASURED_DIM],
    /// Whether the step runs its loops in AVX registers (x86-64 with AVX; the same bits).
    wide: bool,
}

/// One env's filter state: the estimate `z`, the last command sent `u` (flap-limit units), and
/// whether the next observation starts an episode; plus its scratch space.
#[derive(Debug, Clone, PartialEq)]
pub struct FilterState {
    /// The estimate `z = (dx, w, r, r')`.
    pub z: Vec<f64>,
    /// The command the next prediction uses.
    pub u: [f64; ACT_DIM],
    /// Whether the next observation initialises the estimate (one update from zero).
    pub fresh: bool,
    prior: Vec<f64>,
}

impl FilterState {
    /// A state that starts afresh at its next observation.
    pub fn new(nz: usize) -> Self {
        Self {
            z: vec![0.0; nz],
            u: [0.0; ACT_DIM],
            fresh: true,
            prior: vec![0.0; nz],
        }
    }
}

impl LqrFilter {
    /// The step's form of a design.
    pub fn new(design: &LqrDesign) -> Self {
        Self::from_parts(
            design.n,
            &design.f,
            &design.g,
            &design.h,
            &design.l,
            &design.k,
            &design.k_ff,
            design.y_trim,
        )
        .expect("a design's matrices have its shapes")
    }

    /// The filter from a design's matrices (`n` plant states; `F` nz x nz, `G` nz x 4, `H`
    /// 24 x nz, `L` nz x 24, `K` 4 x n, `K_ff` 4 x 4, `nz = n + 8`): an error naming the
    /// matrix whose shape does not fit, or a non-finite entry.
    #[allow(clippy::too_many_arguments)]
    pub fn from_parts(
        n: usize,
        f: &Matrix,
        g: &Matrix,
        h: &Matrix,
        l: &Matrix,
        k: &Matrix,
        k_ff: &Matrix,
        y_trim: [f64; MEASURED_DIM],
    ) -> Result<Self> {
        let nz = n + EXTRA_STATES;
        let shapes = [
            ("f", f, (nz, nz)),
            ("g", g, (nz, ACT_DIM)),
            ("h", h, (MEASURED_DIM, nz)),
            ("l", l, (nz, MEASURED_DIM)),
            ("k", k, (ACT_DIM, n)),
            ("k_ff", k_ff, (ACT_DIM, WIND_DIM + 2)),
        ];
        for (name, m, (rows, cols)) in shapes {
            if (m.rows(), m.cols()) != (rows, cols) {
                return Err(SimError::invalid_config(
                    &format!("lqr.{name}"),
                    format!("a {} x {} matrix", m.rows(), m.cols()),
                    &format!("a {rows} x {cols} matrix"),
                ));
            }
            if !m.is_finite() {
                return Err(SimError::invalid_config(
                    &format!("lqr.{name}"),
                    "a matrix with non-finite entries",
                    "finite entries",
                ));
            }
        }
        if y_trim.iter().any(|y| !y.is_finite()) {
            return Err(SimError::invalid_config(
                "lqr.y_trim",
                "non-finite entries",
                "finite entries",
            ));
        }
        Ok(Self {
            n,
            ft: f.transpose(),
            gt: g.transpose(),
            ht: h.transpose(),
            lt: l.transpose(),
            kt: k.transpose(),
            kfft: k_ff.transpose(),
            y_trim,
            wide: has_avx(),
        })
    }

    /// The same filter with its loops in the processor's baseline registers only (SSE2 on
    /// x86-64): for checking that the vector width changes no bit.
    pub fn baseline_width(mut self) -> Self {
        self.wide = false;
        self
    }

    /// Plant states `n`.
    pub fn n(&self) -> usize {
        self.n
    }

    /// Observer states `nz`.
    pub fn nz(&self) -> usize {
        self.n + EXTRA_STATES
    }

    /// A state for this filter that starts afresh.
    pub fn new_state(&self) -> FilterState {
        FilterState::new(self.nz())
    }

    /// One step for one env: predicts from `state` with its last command, updates with the
    /// observation `obs` (the env's, all 25 entries), writes the command to `command` and keeps
    /// it (as f64) as the command the next prediction uses. [`SimError::Diverged`] if the
    /// command is not finite (an estimate that overflowed): never a NaN command.
    pub fn step(
        &self,
        state: &mut FilterState,
        obs: &[f64; OBS_DIM],
        command: &mut [f32; ACT_DIM],
    ) -> Result<()> {
        #[cfg(target_arch = "x86_64")]
        if self.wide {
            // SAFETY: `wide` is set only where the processor has AVX (`has_avx`).
            return unsafe { self.step_avx(state, obs, command) };
        }
        self.step_body(state, obs, command)
    }

    /// [`Self::step`] compiled for AVX: every operation is the same separate multiplication or
    /// addition of the same operands in the same order, four lanes at a time instead of two, so
    /// the bits are those of the baseline build.
    ///
    /// # Safety
    /// The processor must have AVX.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    unsafe fn step_avx(
        &self,
        state: &mut FilterState,
        obs: &[f64; OBS_DIM],
        command: &mut [f32; ACT_DIM],
    ) -> Result<()> {
        self.step_body(state, obs, command)
    }

    #[inline(always)]
    fn step_body(
        &self,
        state: &mut FilterState,
        obs: &[f64; OBS_DIM],
        command: &mut [f32; ACT_DIM],
    ) -> Result<()> {
        debug_assert_eq!(state.z.len(), self.nz());
        for (c, out) in state.prior.chunks_mut(LANES).enumerate() {
            self.predict_chunk(out, c * LANES, &state.z, &state.u, state.fresh);
        }
        self.update(state, obs, command)
    }

    /// Entries `i0..i0 + out.len()` of the prior `F z + G u` (zero for a fresh state): each
    /// entry `0 + z_0 F_i0 + z_1 F_i1 + ... + u_0 G_i0 + ...` in ascending order, the sums of
    /// a chunk kept in registers across the columns.
    #[inline(always)]
    fn predict_chunk(
        &self,
        out: &mut [f64],
        i0: usize,
        z: &[f64],
        u: &[f64; ACT_DIM],
        fresh: bool,
    ) {
        if fresh {
            out.fill(0.0);
        } else {
            sum_chunk(out, i0, [(z, &self.ft), (u, &self.gt)]);
        }
    }

    /// The update and the control law from the prior in `state.prior`.
    #[inline(always)]
    fn update(
        &self,
        state: &mut FilterState,
        obs: &[f64; OBS_DIM],
        command: &mut [f32; ACT_DIM],
    ) -> Result<()> {
        let prior = &state.prior;
        let mut predicted = [0.0; MEASURED_DIM];
        for (j, pj) in prior.iter().enumerate() {
            axpy(&mut predicted, *pj, self.ht.row(j));
        }
        let mut innovation = [0.0; MEASURED_DIM];
        for (m, &i) in MEASURED.iter().enumerate() {
            innovation[m] = (obs[i] - self.y_trim[m]) - predicted[m];
        }
        // z = z- + L innovation: the correction summed first (into z), then the prior added.
        let mut u = [0.0; ACT_DIM];
        let z = &mut state.z;
        for (c, out) in z.chunks_mut(LANES).enumerate() {
            let i0 = c * LANES;
            sum_chunk(out, i0, [(&innovation, &self.lt)]);
            for (zi, pi) in out.iter_mut().zip(&prior[i0..]) {
                *zi += *pi;
            }
        }
        for (j, zj) in z[..self.n].iter().enumerate() {
            axpy(&mut u, -*zj, self.kt.row(j));
        }
        let n = self.n;
        let reference = [z[n], z[n + 1], z[n + WIND_DIM + 1], z[n + WIND_DIM + 2]];
        let mut feedforward = [0.0; ACT_DIM];
        for (r, rr) in reference.iter().enumerate() {
            axpy(&mut feedforward, *rr, self.kfft.row(r));
        }
        for (k, c) in command.iter_mut().enumerate() {
            let v = (u[k] + feedforward[k]).clamp(-1.0, 1.0);
            if !v.is_finite() {
                return Err(SimError::Diverged {
                    time: 0.0,
                    reason: "the LQR's Kalman filter estimate is not finite".into(),
                });
            }
            state.u[k] = v;
            *c = v as f32;
        }
        state.fresh = false;
        Ok(())
    }
}

/// Rows whose predictions are computed together by [`LqrFilter::step_rows`]: each chunk of `F`'s
/// columns is read from memory once per block, then from the L1 cache for the block's other rows.
const BLOCK: usize = 8;

/// Outputs summed together in registers (four AVX or eight SSE2 registers of f64): each
/// matrix row's chunk is read once per step instead of once per output update.
const LANES: usize = 16;

impl LqrFilter {
    /// [`Self::step`] for the rows of a batch that `selected` selects (the others keep their
    /// state and their command), in blocks of rows that share each read of the matrices. Every
    /// row's operations are those of [`Self::step`] in the same order: the same bits, whatever
    /// the batch, its size and the rows selected. Stops at the first row whose command is not
    /// finite ([`SimError::Diverged`]).
    pub fn step_rows(
        &self,
        states: &mut [FilterState],
        obs: &[[f64; OBS_DIM]],
        selected: &[bool],
        commands: &mut [[f32; ACT_DIM]],
    ) -> Result<()> {
        assert!(
            obs.len() == states.len()
                && selected.len() == states.len()
                && commands.len() == states.len(),
            "one observation, selection and command per state"
        );
        #[cfg(target_arch = "x86_64")]
        if self.wide {
            // SAFETY: `wide` is set only where the processor has AVX (`has_avx`).
            return unsafe { self.step_rows_avx(states, obs, selected, commands) };
        }
        self.step_rows_body(states, obs, selected, commands)
    }

    /// [`Self::step_rows`] compiled for AVX (see [`Self::step_avx`]).
    ///
    /// # Safety
    /// The processor must have AVX.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    unsafe fn step_rows_avx(
        &self,
        states: &mut [FilterState],
        obs: &[[f64; OBS_DIM]],
        selected: &[bool],
        commands: &mut [[f32; ACT_DIM]],
    ) -> Result<()> {
        self.step_rows_body(states, obs, selected, commands)
    }

    #[inline(always)]
    fn step_rows_body(
        &self,
        states: &mut [FilterState],
        obs: &[[f64; OBS_DIM]],
        selected: &[bool],
        commands: &mut [[f32; ACT_DIM]],
    ) -> Result<()> {
        let nz = self.nz();
        for start in (0..states.len()).step_by(BLOCK) {
            let end = (start + BLOCK).min(states.len());
            let block = &mut states[start..end];
            let chosen = &selected[start..end];
            for i0 in (0..nz).step_by(LANES) {
                let i1 = (i0 + LANES).min(nz);
                for (s, &c) in block.iter_mut().zip(chosen) {
                    if c {
                        debug_assert_eq!(s.z.len(), nz);
                        let FilterState { z, u, fresh, prior } = s;
                        self.predict_chunk(&mut prior[i0..i1], i0, z, u, *fresh);
                    }
                }
            }
            for (r, s) in block.iter_mut().enumerate() {
                if chosen[r] {
                    self.update(s, &obs[start + r], &mut commands[start + r])?;
                }
            }
        }
        Ok(())
    }
}

/// Whether the processor has AVX (cached by the standard library after the first call).
fn has_avx() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// `out[l] = 0 + sum over the terms (a, m), in order, of a_j m[j][i0 + l]` (each `j` ascending):
/// in registers for a whole chunk of [`LANES`] outputs, else (the last, shorter chunk) in memory,
/// the same operations in the same order either way.
#[inline(always)]
fn sum_chunk<const T: usize>(out: &mut [f64], i0: usize, terms: [(&[f64], &Matrix); T]) {
    match <&mut [f64; LANES]>::try_from(&mut *out) {
        Ok(out) => {
            let mut acc = [0.0; LANES];
            for (a, m) in terms {
                accumulate(&mut acc, i0, a, m);
            }
            *out = acc;
        }
        Err(_) => {
            out.fill(0.0);
            for (a, m) in terms {
                accumulate_tail(out, i0, a, m);
            }
        }
    }
}

/// `acc[l] += a_j m[j][i0 + l]` for every `j` in ascending order: each output one separate
/// multiplication and addition per term, the outputs kept in registers.
#[inline(always)]
fn accumulate(acc: &mut [f64; LANES], i0: usize, a: &[f64], m: &Matrix) {
    for (j, aj) in a.iter().enumerate() {
        let column: &[f64; LANES] = m.row(j)[i0..i0 + LANES]
            .try_into()
            .expect("a chunk of LANES columns");
        for (o, x) in acc.iter_mut().zip(column) {
            *o += *aj * x;
        }
    }
}

/// [`accumulate`] for a last chunk shorter than [`LANES`]: the same operations in the same order.
#[inline(always)]
fn accumulate_tail(acc: &mut [f64], i0: usize, a: &[f64], m: &Matrix) {
    for (j, aj) in a.iter().enumerate() {
        axpy(acc, *aj, &m.row(j)[i0..i0 + acc.len()]);
    }
}

/// `y += a x`, element by element (each output one addition: vectorizes across outputs).
#[inline]
fn axpy(y: &mut [f64], a: f64, x: &[f64]) {
    debug_assert_eq!(y.len(), x.len());
    for (yi, xi) in y.iter_mut().zip(x) {
        *yi += a * xi;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Deterministic pseudo-random matrices `(F, G, H, L, K, K_ff)` of a design of `n` plant
    /// states, from `seed`.
    fn matrices(n: usize, mut seed: u64) -> [Matrix; 6] {
        let nz = n + EXTRA_STATES;
        let mut next = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let mut m = |r: usize, c: usize, s: f64| Matrix::from_fn(r, c, |_, _| s * next());
        [
            m(nz, nz, 0.1),
            m(nz, ACT_DIM, 1.0),
            m(MEASURED_DIM, nz, 1.0),
            m(nz, MEASURED_DIM, 0.1),
            m(ACT_DIM, n, 0.2),
            m(ACT_DIM, 4, 1.0),
        ]
    }

    /// A filter of `n` plant states with deterministic pseudo-random matrices.
    fn filter(n: usize) -> LqrFilter {
        let [f, g, h, l, k, k_ff] = matrices(n, 0x2545_f491_4f6c_dd1d);
        LqrFilter::from_parts(n, &f, &g, &h, &l, &k, &k_ff, [0.01; MEASURED_DIM]).unwrap()
    }

    #[test]
    fn the_vector_width_changes_no_bit() {
        let wide = filter(37);
        let narrow = wide.clone().baseline_width();
        let (mut a, mut b) = (wide.new_state(), narrow.new_state());
        for step in 0..20 {
            let obs: [f64; OBS_DIM] = std::array::from_fn(|i| ((i * 7 + step) % 11) as f64 * 0.03);
            let (mut ua, mut ub) = ([0.0_f32; ACT_DIM], [0.0_f32; ACT_DIM]);
            wide.step(&mut a, &obs, &mut ua).unwrap();
            narrow.step(&mut b, &obs, &mut ub).unwrap();
            assert_eq!(ua.map(f32::to_bits), ub.map(f32::to_bits), "step {step}");
            assert!(a
                .z
                .iter()
                .zip(&b.z)
                .all(|(x, y)| x.to_bits() == y.to_bits()));
        }
    }

    /// The step as the module docs write it, each sum a plain loop over its index in ascending
    /// order from 0 (the arithmetic the filter promises, whatever its loops' layout).
    #[allow(clippy::too_many_arguments)]
    fn reference_step(
        f: &Matrix,
        g: &Matrix,
        h: &Matrix,
        l: &Matrix,
        k: &Matrix,
        k_ff: &Matrix,
        y_trim: &[f64; MEASURED_DIM],
        state: &mut FilterState,
        obs: &[f64; OBS_DIM],
    ) -> [f32; ACT_DIM] {
        let (nz, n) = (f.rows(), k.cols());
        let prior: Vec<f64> = (0..nz)
            .map(|i| {
                if state.fresh {
                    return 0.0;
                }
                let mut s = 0.0;
                for j in 0..nz {
                    s += state.z[j] * f[(i, j)];
                }
                for c in 0..ACT_DIM {
                    s += state.u[c] * g[(i, c)];
                }
                s
            })
            .collect();
        let mut innovation = [0.0; MEASURED_DIM];
        for (m, &i) in MEASURED.iter().enumerate() {
            let mut predicted = 0.0;
            for j in 0..nz {
                predicted += prior[j] * h[(m, j)];
            }
            innovation[m] = (obs[i] - y_trim[m]) - predicted;
        }
        for i in 0..nz {
            let mut s = 0.0;
            for m in 0..MEASURED_DIM {
                s += innovation[m] * l[(i, m)];
            }
            state.z[i] = s + prior[i];
        }
        let z = &state.z;
        let reference = [z[n], z[n + 1], z[n + WIND_DIM + 1], z[n + WIND_DIM + 2]];
        std::array::from_fn(|c| {
            let mut u = 0.0;
            for j in 0..n {
                u += -z[j] * k[(c, j)];
            }
            let mut ff = 0.0;
            for r in 0..4 {
                ff += reference[r] * k_ff[(c, r)];
            }
            let v = (u + ff).clamp(-1.0, 1.0);
            state.u[c] = v;
            v as f32
        })
    }

    #[test]
    fn a_step_is_the_plain_sums_in_ascending_order() {
        // 37 plant states: 45 observer states, two chunks of LANES and a shorter last one.
        let n = 37;
        let [f, g, h, l, k, k_ff] = matrices(n, 0x9e37_79b9_7f4a_7c15);
        let y_trim = [0.01; MEASURED_DIM];
        for filter in [
            LqrFilter::from_parts(n, &f, &g, &h, &l, &k, &k_ff, y_trim).unwrap(),
            LqrFilter::from_parts(n, &f, &g, &h, &l, &k, &k_ff, y_trim)
                .unwrap()
                .baseline_width(),
        ] {
            let (mut ours, mut plain) = (filter.new_state(), filter.new_state());
            for step in 0..15 {
                let obs: [f64; OBS_DIM] =
                    std::array::from_fn(|i| ((i * 7 + step * 3) % 11) as f64 * 0.07 - 0.3);
                let mut u = [0.0_f32; ACT_DIM];
                filter.step(&mut ours, &obs, &mut u).unwrap();
                let expected = reference_step(&f, &g, &h, &l, &k, &k_ff, &y_trim, &mut plain, &obs);
                plain.fresh = false;
                assert_eq!(
                    u.map(f32::to_bits),
                    expected.map(f32::to_bits),
                    "step {step}"
                );
                let bits = |s: &FilterState| s.z.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&ours), bits(&plain), "step {step}");
            }
        }
    }

    #[test]
    fn rows_stepped_in_blocks_are_rows_stepped_alone() {
        let f = filter(23);
        let rows = 11;
        let mut alone: Vec<FilterState> = (0..rows).map(|_| f.new_state()).collect();
        let mut batch = alone.clone();
        let mut out = vec![[0.0_f32; ACT_DIM]; rows];
        for step in 0..12 {
            let obs: Vec<[f64; OBS_DIM]> = (0..rows)
                .map(|r| std::array::from_fn(|i| ((i * 5 + r * 3 + step) % 13) as f64 * 0.02))
                .collect();
            let selected: Vec<bool> = (0..rows).map(|r| (r + step) % 3 != 0).collect();
            if step == 6 {
                batch[4].fresh = true;
                alone[4].fresh = true;
            }
            f.step_rows(&mut batch, &obs, &selected, &mut out).unwrap();
            for r in 0..rows {
                if selected[r] {
                    let mut u = [0.0_f32; ACT_DIM];
                    f.step(&mut alone[r], &obs[r], &mut u).unwrap();
                    assert_eq!(u.map(f32::to_bits), out[r].map(f32::to_bits), "row {r}");
                }
                assert_eq!(alone[r], batch[r], "row {r} at step {step}");
            }
        }
    }

    #[test]
    fn a_filter_with_a_wrong_shape_names_the_matrix() {
        let n = 5;
        let nz = n + EXTRA_STATES;
        let z = |r, c| Matrix::zeros(r, c);
        let err = LqrFilter::from_parts(
            n,
            &z(nz, nz),
            &z(nz, ACT_DIM),
            &z(MEASURED_DIM, nz),
            &z(nz, MEASURED_DIM + 1),
            &z(ACT_DIM, n),
            &z(ACT_DIM, 4),
            [0.0; MEASURED_DIM],
        )
        .unwrap_err();
        assert!(err.to_string().contains("`lqr.l`"), "{err}");
    }
}
