//! A measurement for issue 12's open targets, not part of the model: what the backward sweep
//! (`recursive.rs`) costs per env when four envs' chains run through it together, one env per
//! AVX2 lane ("lockstep envs", design note 26), against one env at a time with the same
//! expressions in scalar fused arithmetic.
//!
//! The sweep here is the library's scalar sweep written once over a lane type (`f64`, or four
//! `f64` in an `__m256d`), on random well-conditioned chains (directions from random angles, an
//! articulated inertia starting at the tip mass); each lane repeats the scalar expression, and the
//! program checks that lane j of the four-wide run equals the scalar run of chain j bit for bit.
//!
//! `cargo run --release -p accd-tether --example lockstep_sweep -- [n] [rounds]`
#[cfg(target_arch = "x86_64")]
mod lanes {
    use std::arch::x86_64::*;

    /// What the sweep needs of a number: one f64, or four in lockstep.
    pub trait Lane: Copy {
        fn splat(v: f64) -> Self;
        fn add(self, o: Self) -> Self;
        fn sub(self, o: Self) -> Self;
        fn mul(self, o: Self) -> Self;
        fn div(self, o: Self) -> Self;
        fn neg(self) -> Self;
        /// `a * b + c`, fused.
        fn madd(a: Self, b: Self, c: Self) -> Self;
    }

    impl Lane for f64 {
        #[inline(always)]
        fn splat(v: f64) -> Self {
            v
        }
        #[inline(always)]
        fn add(self, o: Self) -> Self {
            self + o
        }
        #[inline(always)]
        fn sub(self, o: Self) -> Self {
            self - o
        }
        #[inline(always)]
        fn mul(self, o: Self) -> Self {
            self * o
        }
        #[inline(always)]
        fn div(self, o: Self) -> Self {
            self / o
        }
        #[inline(always)]
        fn neg(self) -> Self {
            -self
        }
        #[inline(always)]
        fn madd(a: Self, b: Self, c: Self) -> Self {
            a.mul_add(b, c)
        }
    }

    /// Four envs, one per lane.
    #[derive(Clone, Copy)]
    pub struct X4(pub __m256d);

    impl Lane for X4 {
        #[inline(always)]
        fn splat(v: f64) -> Self {
            unsafe { X4(_mm256_set1_pd(v)) }
        }
        #[inline(always)]
        fn add(self, o: Self) -> Self {
            unsafe { X4(_mm256_add_pd(self.0, o.0)) }
        }
        #[inline(always)]
        fn sub(self, o: Self) -> Self {
            unsafe { X4(_mm256_sub_pd(self.0, o.0)) }
        }
        #[inline(always)]
        fn mul(self, o: Self) -> Self {
            unsafe { X4(_mm256_mul_pd(self.0, o.0)) }
        }
        #[inline(always)]
        fn div(self, o: Self) -> Self {
            unsafe { X4(_mm256_div_pd(self.0, o.0)) }
        }
        #[inline(always)]
        fn neg(self) -> Self {
            unsafe { X4(_mm256_xor_pd(self.0, _mm256_set1_pd(-0.0))) }
        }
        #[inline(always)]
        fn madd(a: Self, b: Self, c: Self) -> Self {
            unsafe { X4(_mm256_fmadd_pd(a.0, b.0, c.0)) }
        }
    }

    /// One chain (or four in lockstep), per segment, as the sweep reads it.
    pub struct Chain<L> {
        pub ep: Vec<[L; 2]>,
        pub es: Vec<[L; 3]>,
        pub cos_psi: Vec<L>,
        pub force: Vec<[L; 3]>,
        pub reduced: Vec<[L; 3]>,
        pub w: Vec<[L; 3]>,
        pub tip_force: [L; 3],
    }

    /// What the sweep leaves per segment: the rows of `l G` and `y`.
    #[derive(Clone, Copy)]
    pub struct Out<L> {
        pub lg: [[L; 3]; 2],
        pub y: [L; 2],
    }

    #[inline(always)]
    fn dot<L: Lane>(a: &[L; 3], b: &[L; 3]) -> L {
        L::madd(a[0], b[0], L::madd(a[1], b[1], a[2].mul(b[2])))
    }
    #[inline(always)]
    fn dot_xz<L: Lane>(a: &[L; 2], b: &[L; 3]) -> L {
        L::madd(a[0], b[0], a[1].mul(b[2]))
    }
    #[inline(always)]
    fn axpy<L: Lane>(x: &[L; 3], a: L, y: &[L; 3]) -> [L; 3] {
        [
            L::madd(x[0], a, y[0]),
            L::madd(x[1], a, y[1]),
            L::madd(x[2], a, y[2]),
        ]
    }
    #[inline(always)]
    fn scale<L: Lane>(x: &[L; 3], a: L) -> [L; 3] {
        [x[0].mul(a), x[1].mul(a), x[2].mul(a)]
    }
    #[inline(always)]
    fn sub3<L: Lane>(x: &[L; 3], y: &[L; 3]) -> [L; 3] {
        [x[0].sub(y[0]), x[1].sub(y[1]), x[2].sub(y[2])]
    }

    /// Symmetric 3x3: xx, yy, zz, xy, xz, yz.
    #[inline(always)]
    fn sym_mul<L: Lane>(b: &[L; 6], v: &[L; 3]) -> [L; 3] {
        [
            L::madd(b[0], v[0], L::madd(b[3], v[1], b[4].mul(v[2]))),
            L::madd(b[3], v[0], L::madd(b[1], v[1], b[5].mul(v[2]))),
            L::madd(b[4], v[0], L::madd(b[5], v[1], b[2].mul(v[2]))),
        ]
    }
    #[inline(always)]
    fn sym_mul_xz<L: Lane>(b: &[L; 6], v: &[L; 2]) -> [L; 3] {
        [
            L::madd(b[0], v[0], b[4].mul(v[1])),
            L::madd(b[3], v[0], b[5].mul(v[1])),
            L::madd(b[4], v[0], b[2].mul(v[1])),
        ]
    }

    /// The backward sweep of `recursive.rs` (tip to segment 2), the same expressions in the same
    /// order, over any lane type; returns `B_1`, `b_1`.
    #[inline(always)]
    pub fn backward<L: Lane>(
        chain: &Chain<L>,
        l: f64,
        m: f64,
        tip_mass: f64,
        out: &mut [Out<L>],
    ) -> ([L; 6], [L; 3]) {
        let n = chain.ep.len();
        let (lv, mv, m6) = (L::splat(l), L::splat(m), L::splat(m / 6.0));
        let inv_l = L::splat(1.0 / l);
        let d = L::splat(tip_mass + 0.5 * m);
        let zero = L::splat(0.0);
        let mut bm = [d, d, d, zero, zero, zero];
        let mut bias = chain.tip_force;
        for k in (1..n).rev() {
            let (ep, es) = (&chain.ep[k], &chain.es[k]);
            let (force, reduced, w) = (&chain.force[k], &chain.reduced[k], &chain.w[k]);
            let cos_psi = chain.cos_psi[k];
            let bep = sym_mul_xz(&bm, ep);
            let bes = sym_mul(&bm, es);
            let k00 = L::madd(m6.mul(cos_psi).neg(), cos_psi, dot_xz(ep, &bep));
            let k01 = dot_xz(ep, &bes);
            let k11 = dot(es, &bes).sub(m6);
            let a0 = axpy(&bes, k01.neg(), &scale(&bep, k11));
            let a1 = axpy(&bep, k01.neg(), &scale(&bes, k00));
            let det = L::madd(k00, k11, k01.mul(k01).neg());
            let inv = L::splat(1.0).div(det);
            let bw = sym_mul(&bm, w);
            let v = axpy(&bias, inv_l, &sub3(reduced, &bw));
            let (r0, r1) = (dot_xz(ep, &v), dot(es, &v));
            let y0 = L::madd(k11, r0, k01.mul(r1).neg()).mul(inv);
            let y1 = L::madd(k00, r1, k01.mul(r0).neg()).mul(inv);
            let t = axpy(&bep, y0, &axpy(&bes, y1, &bw));
            let fb = [
                force[0].add(bias[0]),
                force[1].add(bias[1]),
                force[2].add(bias[2]),
            ];
            bias = axpy(&t, lv.neg(), &fb);
            let upd =
                |a: L, b: L, c: L, d: L, base: L| L::madd(L::madd(a, b, c.mul(d)).neg(), inv, base);
            bm = [
                upd(a0[0], bep[0], a1[0], bes[0], bm[0].add(mv)),
                upd(a0[1], bep[1], a1[1], bes[1], bm[1].add(mv)),
                upd(a0[2], bep[2], a1[2], bes[2], bm[2].add(mv)),
                upd(a0[0], bep[1], a1[0], bes[1], bm[3]),
                upd(a0[0], bep[2], a1[0], bes[2], bm[4]),
                upd(a0[1], bep[2], a1[1], bes[2], bm[5]),
            ];
            out[k] = Out {
                lg: [scale(&a0, inv), scale(&a1, inv)],
                y: [y0, y1],
            };
        }
        (bm, bias)
    }

    /// The forward sweep of `recursive.rs` (segment 2 to the tip) from the acceleration `acc`
    /// of segment 2's base, writing the angle accelerations into `qdd` (2 per segment).
    #[inline(always)]
    pub fn forward<L: Lane>(
        chain: &Chain<L>,
        out: &[Out<L>],
        l: f64,
        mut acc: [L; 3],
        qdd: &mut [[L; 2]],
    ) -> [L; 3] {
        let n = chain.ep.len();
        let (lv, inv_l) = (L::splat(l), L::splat(-1.0 / l));
        let zero = L::splat(0.0);
        for k in 1..n {
            let art = &out[k];
            let (d0, d1) = (dot(&art.lg[0], &acc), dot(&art.lg[1], &acc));
            qdd[k] = [L::madd(inv_l, d0, art.y[0]), L::madd(inv_l, d1, art.y[1])];
            let ep = [chain.ep[k][0], zero, chain.ep[k][1]];
            let es = &chain.es[k];
            let phi = axpy(&ep, art.y[0], &axpy(es, art.y[1], &chain.w[k]));
            let shifted = axpy(&phi, lv, &acc);
            acc = axpy(&ep, d0.neg(), &axpy(es, d1.neg(), &shifted));
        }
        acc
    }

    /// Both sweeps (backward, a stand-in for the root's solution, forward), compiled for AVX2
    /// and FMA, for one env (`f64`) or four ([`X4`]); returns the tip's acceleration.
    #[target_feature(enable = "avx2,fma")]
    pub unsafe fn sweeps<L: Lane>(
        c: &Chain<L>,
        l: f64,
        m: f64,
        tip: f64,
        out: &mut [Out<L>],
        qdd: &mut [[L; 2]],
    ) -> [L; 3] {
        let (bm, bias) = backward(c, l, m, tip, out);
        // Segment 2's base acceleration from B_1 and b_1, in place of the root's 3x3 solve.
        let acc = [bias[0].div(bm[0]), bias[1].div(bm[1]), bias[2].div(bm[2])];
        forward(c, out, l, acc, qdd)
    }

    /// The backward sweep alone, compiled for AVX2 and FMA.
    #[target_feature(enable = "avx2,fma")]
    pub unsafe fn backward_avx2<L: Lane>(
        c: &Chain<L>,
        l: f64,
        m: f64,
        tip: f64,
        out: &mut [Out<L>],
    ) -> ([L; 6], [L; 3]) {
        backward(c, l, m, tip, out)
    }

    pub fn lane(v: X4, j: usize) -> f64 {
        let mut a = [0.0; 4];
        unsafe { _mm256_storeu_pd(a.as_mut_ptr(), v.0) };
        a[j]
    }

    pub fn pack(v: [f64; 4]) -> X4 {
        unsafe { X4(_mm256_loadu_pd(v.as_ptr())) }
    }
}

#[cfg(target_arch = "x86_64")]
fn main() {
    use lanes::*;
    use std::time::Instant;

    if !(std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma"))
    {
        println!("needs AVX2 and FMA");
        return;
    }
    let args: Vec<String> = std::env::args().collect();
    let n: usize = args.get(1).map_or(30, |a| a.parse().unwrap());
    let rounds: usize = args.get(2).map_or(20, |a| a.parse().unwrap());
    // Table 3's segment: 250 m / n, 0.437 kg/m; the ACCD's 50 kg at the tip.
    let l = 250.0 / n as f64;
    let m = 0.437 * l;
    let tip = 50.0;
    // A small deterministic generator (xorshift), so that every run sees the same chains.
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let mut uniform = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    let chains: Vec<Chain<f64>> = (0..4)
        .map(|_| {
            let mut c = Chain {
                ep: vec![],
                es: vec![],
                cos_psi: vec![],
                force: vec![],
                reduced: vec![],
                w: vec![],
                tip_force: [
                    100.0 * uniform(),
                    50.0 * uniform(),
                    500.0 + 100.0 * uniform(),
                ],
            };
            for _ in 0..n {
                let (phi, psi) = (0.3 * uniform(), 0.2 * uniform());
                let (sf, cf, sp, cp) = (phi.sin(), phi.cos(), psi.sin(), psi.cos());
                c.ep.push([cp * sf, cp * cf]);
                c.es.push([sp * cf, cp, -sp * sf]);
                c.cos_psi.push(cp);
                c.force
                    .push([10.0 * uniform(), 10.0 * uniform(), 40.0 + 10.0 * uniform()]);
                c.reduced.push([uniform(), uniform(), uniform()]);
                c.w.push([0.1 * uniform(), 0.1 * uniform(), 0.1 * uniform()]);
            }
            c
        })
        .collect();
    let x4 = |f: &dyn Fn(&Chain<f64>) -> f64| {
        pack([f(&chains[0]), f(&chains[1]), f(&chains[2]), f(&chains[3])])
    };
    let lockstep = Chain {
        ep: (0..n)
            .map(|k| [0, 1].map(|i| x4(&|c| c.ep[k][i])))
            .collect(),
        es: (0..n)
            .map(|k| [0, 1, 2].map(|i| x4(&|c| c.es[k][i])))
            .collect(),
        cos_psi: (0..n).map(|k| x4(&|c| c.cos_psi[k])).collect(),
        force: (0..n)
            .map(|k| [0, 1, 2].map(|i| x4(&|c| c.force[k][i])))
            .collect(),
        reduced: (0..n)
            .map(|k| [0, 1, 2].map(|i| x4(&|c| c.reduced[k][i])))
            .collect(),
        w: (0..n)
            .map(|k| [0, 1, 2].map(|i| x4(&|c| c.w[k][i])))
            .collect(),
        tip_force: [0, 1, 2].map(|i| x4(&|c| c.tip_force[i])),
    };
    let zero1 = Out {
        lg: [[0.0; 3]; 2],
        y: [0.0; 2],
    };
    let z4 = pack([0.0; 4]);
    let zero4 = Out {
        lg: [[z4; 3]; 2],
        y: [z4; 2],
    };
    let mut out1 = vec![vec![zero1; n]; 4];
    let mut out4 = vec![zero4; n];

    // Lane j of the lockstep sweep is chain j's scalar sweep, bit for bit.
    let mut roots = vec![];
    for (j, c) in chains.iter().enumerate() {
        roots.push(unsafe { backward_avx2(c, l, m, tip, &mut out1[j]) });
    }
    let root4 = unsafe { backward_avx2(&lockstep, l, m, tip, &mut out4) };
    let mut same = true;
    for j in 0..4 {
        for i in 0..6 {
            same &= lane(root4.0[i], j).to_bits() == roots[j].0[i].to_bits();
        }
        for k in 1..n {
            for r in 0..2 {
                same &= lane(out4[k].y[r], j).to_bits() == out1[j][k].y[r].to_bits();
                for c in 0..3 {
                    same &= lane(out4[k].lg[r][c], j).to_bits() == out1[j][k].lg[r][c].to_bits();
                }
            }
        }
    }
    println!("lane j of the lockstep sweep equals chain j's scalar sweep bit for bit: {same}");

    // Time: the four chains one after another, against the four in lockstep; best of `rounds`
    // rounds of `reps` sweeps each, alternating.
    let reps = 20_000;
    let (mut best1, mut best4) = (f64::INFINITY, f64::INFINITY);
    let mut sink = 0.0;
    for _ in 0..rounds {
        let t = Instant::now();
        for _ in 0..reps {
            for (j, c) in chains.iter().enumerate() {
                sink +=
                    unsafe { backward_avx2(std::hint::black_box(c), l, m, tip, &mut out1[j]) }.0[0];
            }
        }
        best1 = best1.min(t.elapsed().as_secs_f64());
        let t = Instant::now();
        for _ in 0..reps {
            sink += lane(
                unsafe { backward_avx2(std::hint::black_box(&lockstep), l, m, tip, &mut out4) }.0
                    [0],
                0,
            );
        }
        best4 = best4.min(t.elapsed().as_secs_f64());
    }
    let per = |t: f64| t / (reps * 4 * (n - 1)) as f64 * 1e9;
    println!(
        "n = {n}: backward sweep per env and segment: one env at a time {:.2} ns, four envs in lockstep {:.2} ns ({:.2}x) [{sink:.3e}]",
        per(best1),
        per(best4),
        best1 / best4
    );

    // Both sweeps (backward, a stand-in root, forward), checked and timed the same way.
    let mut qdd1 = vec![vec![[0.0; 2]; n]; 4];
    let mut qdd4 = vec![[z4; 2]; n];
    let tips: Vec<[f64; 3]> = (0..4)
        .map(|j| unsafe { sweeps(&chains[j], l, m, tip, &mut out1[j], &mut qdd1[j]) })
        .collect();
    let tip4 = unsafe { sweeps(&lockstep, l, m, tip, &mut out4, &mut qdd4) };
    let mut same = true;
    for j in 0..4 {
        for i in 0..3 {
            same &= lane(tip4[i], j).to_bits() == tips[j][i].to_bits();
        }
        for k in 1..n {
            for r in 0..2 {
                same &= lane(qdd4[k][r], j).to_bits() == qdd1[j][k][r].to_bits();
            }
        }
    }
    println!("both sweeps, lane j equals chain j bit for bit: {same}");
    let (mut best1, mut best4) = (f64::INFINITY, f64::INFINITY);
    for _ in 0..rounds {
        let t = Instant::now();
        for _ in 0..reps {
            for (j, c) in chains.iter().enumerate() {
                sink += unsafe {
                    sweeps(
                        std::hint::black_box(c),
                        l,
                        m,
                        tip,
                        &mut out1[j],
                        &mut qdd1[j],
                    )
                }[0];
            }
        }
        best1 = best1.min(t.elapsed().as_secs_f64());
        let t = Instant::now();
        for _ in 0..reps {
            sink += lane(
                unsafe {
                    sweeps(
                        std::hint::black_box(&lockstep),
                        l,
                        m,
                        tip,
                        &mut out4,
                        &mut qdd4,
                    )
                }[0],
                0,
            );
        }
        best4 = best4.min(t.elapsed().as_secs_f64());
    }
    println!(
        "n = {n}: both sweeps per env and segment: one env at a time {:.2} ns, four envs in lockstep {:.2} ns ({:.2}x) [{sink:.3e}]",
        per(best1),
        per(best4),
        best1 / best4
    );
}

#[cfg(not(target_arch = "x86_64"))]
fn main() {
    println!("x86_64 only");
}
