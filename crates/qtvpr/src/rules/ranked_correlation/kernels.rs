//! The vector loops of semantics §4, at the bottom of it: standardising a profile,
//! correlating it with a group of profiles, and the screen's block summaries and
//! bounds. Each is compiled for the widest vectors the CPU has (pulp) and sums in
//! fixed lanes ([`LANES`]) and a fixed order, so every CPU, and every grouping, gets
//! the same bits. It imports nothing of the rule.

use crate::input::Score;

/// How many correlations [`Correlations`] sums in one pass (`Ranked::correlations`).
pub(super) const GROUP: usize = 4;

/// How a sorted profile is centred and scaled to unit norm: `(x * inv_scale - mean) *
/// inv_norm`, where `inv_scale` is a power of two that keeps squares from overflowing
/// or underflowing (so scaling is exact), and `inv_norm` is 0 for a constant profile.
#[derive(Debug, Clone, Copy)]
pub(super) struct Standard {
    inv_scale: f64,
    mean: f64,
    inv_norm: f64,
}

impl Standard {
    pub(super) const CONSTANT: Self = Self {
        inv_scale: 1.0,
        mean: 0.0,
        inv_norm: 0.0,
    };

    /// The standardisation of a sorted, finite profile. Zero variance is tested exactly
    /// (first == last), not as a small norm.
    #[inline(always)]
    fn of<T: Score>(profile: &[T]) -> Self {
        let (first, last) = (profile[0].to_f64(), profile[profile.len() - 1].to_f64());
        if first == last {
            return Self::CONSTANT;
        }
        // 2^-e for the exponent e of the largest magnitude, within range both ways.
        let exponent = first.abs().max(last.abs()).log2().floor().clamp(-1000.0, 1000.0);
        let inv_scale = (-exponent).exp2();
        let mean = sum_lanes(profile, profile, |x, _| x.to_f64() * inv_scale) / profile.len() as f64;
        let centred = Self {
            inv_scale,
            mean,
            inv_norm: 1.0,
        };
        let norm = sum_lanes(profile, profile, |x, _| centred.apply(x).powi(2)).sqrt();
        Self {
            inv_norm: 1.0 / norm,
            ..centred
        }
    }

    #[inline(always)]
    pub(super) fn apply<T: Score>(self, x: T) -> f64 {
        (x.to_f64() * self.inv_scale - self.mean) * self.inv_norm
    }
}

/// The correlations of a standardised profile `u` with [`GROUP`] sorted columns,
/// compiled for the widest vectors the CPU has: each column's sum in the lanes and
/// order of [`sum_lanes`], so every CPU, and every grouping, gets the same bits.
pub(super) struct Correlations<'a, T> {
    pub(super) u: &'a [f64],
    pub(super) columns: [&'a [T]; GROUP],
    pub(super) standard: [Standard; GROUP],
}

impl<T: Score> Correlations<'_, T> {
    /// The group's sums: in explicit 8-lane vectors where the CPU has AVX-512 or AVX2,
    /// else as the compiler vectorises them.
    ///
    /// Explicit, because the compiler's own vectorisation of four columns' 32 lanes in
    /// one loop was a lottery: some builds packed the lanes across columns (a score of
    /// each column in a vector, gathered by scalar inserts) or left them scalar, 2.5 to
    /// 3.5x slower, and which a build got changed with unrelated code elsewhere in the
    /// crate. The vectors hold each column's lanes in order and do the scalar code's
    /// operations, so every path gives the same bits.
    #[inline]
    pub(super) fn sums(self, arch: pulp::Arch) -> [f64; GROUP] {
        #[cfg(target_arch = "x86_64")]
        {
            if let Some(simd) = pulp::x86::V4::try_new() {
                return pulp::Simd::vectorize(simd, Explicit(simd, self));
            }
            if let Some(simd) = pulp::x86::V3::try_new() {
                return pulp::Simd::vectorize(simd, Explicit(simd, self));
            }
        }
        arch.dispatch(self)
    }

    /// Each column's 8 lane sums, from `lanes` over the whole chunks of `u`, and the
    /// tail after them: the order of [`sum_lanes`].
    #[inline(always)]
    fn finish(self, lanes: [[f64; LANES]; GROUP]) -> [f64; GROUP] {
        let Self { u, columns, standard } = self;
        let body = u.len() / LANES * LANES;
        std::array::from_fn(|m| {
            let tail: f64 = (u[body..].iter().zip(&columns[m][body..]))
                .map(|(&a, &x)| a * standard[m].apply(x))
                .sum();
            lanes[m].iter().sum::<f64>() + tail
        })
    }

    /// Each column's whole chunks of 8 scores, as many as `u` has.
    #[inline(always)]
    fn chunks(&self) -> [&[[T; LANES]]; GROUP] {
        let n = self.u.len() / LANES;
        std::array::from_fn(|m| &self.columns[m][..n * LANES].as_chunks().0[..n])
    }
}

/// The interleaved lanes of every sum here ([`sum_lanes`], the correlations' kernels
/// and the block summaries): they fix each sum's order, and so its bits.
const LANES: usize = 8;

/// The portable kernel (no AVX2): the same operations, lane by lane.
impl<T: Score> pulp::WithSimd for Correlations<'_, T> {
    type Output = [f64; GROUP];

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) -> [f64; GROUP] {
        let (u8, _) = self.u.as_chunks::<LANES>();
        let x8 = self.chunks();
        let mut lanes = [[0.0; LANES]; GROUP];
        for (c, u8) in u8.iter().enumerate() {
            for (m, lanes) in lanes.iter_mut().enumerate() {
                for l in 0..LANES {
                    lanes[l] += u8[l] * self.standard[m].apply(x8[m][c][l]);
                }
            }
        }
        self.finish(lanes)
    }
}

/// 8 scores as `f32` when they are, for the explicit kernels' widening loads (the
/// score types are sealed: `f32` or `f64`).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn as_f32<T: Score>(x: &[T; LANES]) -> Option<&[f32; LANES]> {
    (x as &dyn std::any::Any).downcast_ref()
}

/// The 8 lanes of [`sum_lanes`] in the vectors of one x86 level, with the operations of
/// [`Correlations`]' explicit kernel: each does the scalar code's operation in every
/// lane, one vector instruction a vector.
#[cfg(target_arch = "x86_64")]
trait Lanes8: pulp::Simd {
    /// 8 `f64` lanes, in the layout of `[f64; 8]`.
    type V: pulp::bytemuck::Pod;
    fn splat(self, v: f64) -> Self::V;
    /// 8 scores widened to `f64`.
    fn widen<T: Score>(self, x: &[T; LANES]) -> Self::V;
    fn add(self, a: Self::V, b: Self::V) -> Self::V;
    fn sub(self, a: Self::V, b: Self::V) -> Self::V;
    fn mul(self, a: Self::V, b: Self::V) -> Self::V;
    #[inline(always)]
    fn load(x: [f64; LANES]) -> Self::V {
        pulp::bytemuck::cast(x)
    }
    #[inline(always)]
    fn store(v: Self::V) -> [f64; LANES] {
        pulp::bytemuck::cast(v)
    }
}

/// AVX-512: one `f64x8`.
#[cfg(target_arch = "x86_64")]
impl Lanes8 for pulp::x86::V4 {
    type V = pulp::f64x8;
    #[inline(always)]
    fn splat(self, v: f64) -> Self::V {
        self.splat_f64x8(v)
    }
    #[inline(always)]
    fn widen<T: Score>(self, x: &[T; LANES]) -> Self::V {
        match as_f32(x) {
            Some(&x) => self.convert_f32x8_to_f64x8(pulp::bytemuck::cast(x)),
            None => Self::load(x.map(Score::to_f64)),
        }
    }
    #[inline(always)]
    fn add(self, a: Self::V, b: Self::V) -> Self::V {
        self.add_f64x8(a, b)
    }
    #[inline(always)]
    fn sub(self, a: Self::V, b: Self::V) -> Self::V {
        self.sub_f64x8(a, b)
    }
    #[inline(always)]
    fn mul(self, a: Self::V, b: Self::V) -> Self::V {
        self.mul_f64x8(a, b)
    }
}

/// AVX2: two `f64x4`, lanes 0-3 and 4-7.
#[cfg(target_arch = "x86_64")]
impl Lanes8 for pulp::x86::V3 {
    type V = [pulp::f64x4; 2];
    #[inline(always)]
    fn splat(self, v: f64) -> Self::V {
        [self.splat_f64x4(v); 2]
    }
    #[inline(always)]
    fn widen<T: Score>(self, x: &[T; LANES]) -> Self::V {
        match as_f32(x) {
            Some(&x) => {
                let [lo, hi]: [pulp::f32x4; 2] = pulp::bytemuck::cast(x);
                [self.convert_f32x4_to_f64x4(lo), self.convert_f32x4_to_f64x4(hi)]
            }
            None => Self::load(x.map(Score::to_f64)),
        }
    }
    #[inline(always)]
    fn add(self, a: Self::V, b: Self::V) -> Self::V {
        [self.add_f64x4(a[0], b[0]), self.add_f64x4(a[1], b[1])]
    }
    #[inline(always)]
    fn sub(self, a: Self::V, b: Self::V) -> Self::V {
        [self.sub_f64x4(a[0], b[0]), self.sub_f64x4(a[1], b[1])]
    }
    #[inline(always)]
    fn mul(self, a: Self::V, b: Self::V) -> Self::V {
        [self.mul_f64x4(a[0], b[0]), self.mul_f64x4(a[1], b[1])]
    }
}

/// [`Correlations`] in the explicit vectors of `L`: one 8-lane value a column.
#[cfg(target_arch = "x86_64")]
pub(super) struct Explicit<'a, L, T>(pub(super) L, pub(super) Correlations<'a, T>);

#[cfg(target_arch = "x86_64")]
impl<L: Lanes8, T: Score> pulp::WithSimd for Explicit<'_, L, T> {
    type Output = [f64; GROUP];

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) -> [f64; GROUP] {
        let Self(simd, group) = self;
        let standard = group
            .standard
            .map(|s| (simd.splat(s.inv_scale), simd.splat(s.mean), simd.splat(s.inv_norm)));
        let (u8, _) = group.u.as_chunks::<LANES>();
        let x8 = group.chunks();
        let mut acc = [simd.splat(0.0); GROUP];
        for (c, &u) in u8.iter().enumerate() {
            let u = L::load(u);
            for m in 0..GROUP {
                let (inv_scale, mean, inv_norm) = standard[m];
                let x = simd.mul(simd.sub(simd.mul(simd.widen(&x8[m][c]), inv_scale), mean), inv_norm);
                acc[m] = simd.add(acc[m], simd.mul(u, x));
            }
        }
        group.finish(acc.map(L::store))
    }
}

/// [`Standard::of`], compiled for the widest vectors the CPU has (the lanes of
/// [`sum_lanes`] fix the summation order, so every CPU gets the same bits).
pub(super) struct Standardise<'a, T>(pub(super) &'a [T]);

impl<T: Score> pulp::WithSimd for Standardise<'_, T> {
    type Output = Standard;

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) -> Standard {
        Standard::of(self.0)
    }
}

/// The sum of `f(a_i, b_i)` over two equally long slices, in eight interleaved lanes:
/// vectorisable, and the same order every time.
#[inline(always)]
pub(super) fn sum_lanes<A: Copy, B: Copy>(a: &[A], b: &[B], f: impl Fn(A, B) -> f64) -> f64 {
    let (a8, b8) = (a.chunks_exact(LANES), b.chunks_exact(LANES));
    let tail: f64 = a8.remainder().iter().zip(b8.remainder()).map(|(&x, &y)| f(x, y)).sum();
    let mut lanes = [0.0; LANES];
    for (x, y) in a8.zip(b8) {
        for l in 0..LANES {
            lanes[l] += f(x[l], y[l]);
        }
    }
    lanes.iter().sum::<f64>() + tail
}

/// The kernel of the screen's `summarise`, compiled for the widest vectors the CPU has.
pub(super) struct Summarise<'a> {
    pub(super) x: &'a [f64],
    pub(super) edges: &'a [usize],
    pub(super) out: &'a mut [f64],
}

impl pulp::WithSimd for Summarise<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) {
        let blocks = self.edges.len() - 1;
        for (b, w) in self.edges.windows(2).enumerate() {
            let xb = &self.x[w[0]..w[1]];
            let n = xb.len() as f64;
            let centre = (n - 1.0) / 2.0;
            // Pass 1: the sum and the dot product with the centred ramp `t - centre`. A
            // chunk's ramp is the last one's plus LANES: exact (every value is a multiple
            // of 1/2 far below 2^52), so the same bits as `t as f64 - centre` without a
            // conversion a score.
            let first: [f64; LANES] = std::array::from_fn(|l| l as f64 - centre);
            let (mut sum, mut ramp, mut r) = ([0.0; LANES], [0.0; LANES], first);
            let (x8, tail) = xb.as_chunks::<LANES>();
            for x in x8 {
                for l in 0..LANES {
                    sum[l] += x[l];
                    ramp[l] += r[l] * x[l];
                    r[l] += LANES as f64;
                }
            }
            let start = xb.len() - tail.len();
            for (t, &x) in tail.iter().enumerate() {
                sum[0] += x;
                ramp[0] += ((start + t) as f64 - centre) * x;
            }
            let (sum, ramp) = (sum.iter().sum::<f64>(), ramp.iter().sum::<f64>());
            let mean = sum / n;
            // The ramp's unit factor 1 / |t - centre| = 1 / sqrt(n (n^2 - 1) / 12).
            let unit = if xb.len() > 1 {
                1.0 / (n * (n * n - 1.0) / 12.0).sqrt()
            } else {
                0.0
            };
            let a = ramp * unit;
            let slope = a * unit;
            // Pass 2: the norms of the residuals of the mean, and of the mean and ramp; in
            // two loops, which the compiler turns into vector code each (one loop of
            // both it left scalar, twice as slow as the two).
            let (mut s2, mut e2, mut r) = ([0.0; LANES], [0.0; LANES], first);
            for x in x8 {
                for l in 0..LANES {
                    let d = x[l] - mean;
                    s2[l] += d * d;
                }
            }
            for x in x8 {
                for l in 0..LANES {
                    let e = (x[l] - mean) - slope * r[l];
                    e2[l] += e * e;
                    r[l] += LANES as f64;
                }
            }
            for (t, &x) in tail.iter().enumerate() {
                let d = x - mean;
                let e = d - slope * ((start + t) as f64 - centre);
                s2[0] += d * d;
                e2[0] += e * e;
            }
            self.out[b] = sum / n.sqrt();
            self.out[blocks + b] = a;
            self.out[2 * blocks + b] = e2.iter().sum::<f64>().sqrt();
            self.out[3 * blocks + b] = s2.iter().sum::<f64>().sqrt();
        }
    }
}

/// The kernel of `Screen::bounds`: block by block, every calibration profile at once.
pub(super) struct Bounds<'a> {
    pub(super) cal: &'a [f64],
    pub(super) query: &'a [f64],
    pub(super) n_cal: usize,
    pub(super) blocks: usize,
}

impl pulp::WithSimd for Bounds<'_> {
    type Output = (Vec<f64>, Vec<f64>);

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) -> (Vec<f64>, Vec<f64>) {
        let (n, blocks) = (self.n_cal, self.blocks);
        let (mut lower, mut upper) = (vec![0.0; n], vec![0.0; n]);
        let field = |f: usize, b: usize| &self.cal[(f * blocks + b) * n..(f * blocks + b + 1) * n];
        for b in 0..blocks {
            let q = |f: usize| self.query[f * blocks + b];
            let (qp, qa, qe, qs) = (q(0), q(1), q(2), q(3));
            let (p, a, e, s) = (field(0, b), field(1, b), field(2, b), field(3, b));
            for i in 0..n {
                let base = p[i] * qp;
                let (aa, ee) = (a[i] * qa, e[i] * qe);
                lower[i] += base + (aa - ee).max(0.0);
                upper[i] += base + (s[i] * qs).min(aa + ee);
            }
        }
        (lower, upper)
    }
}
