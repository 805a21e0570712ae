//! Sub-pixel corner refinement (cornerSubPix-style) and its uncertainty.
//!
//! The ChESS corners from calib-targets are good to ~0.2 px, short of the
//! 0.1 px calibration needs. At a true X-junction every image gradient in a
//! small window is orthogonal to the vector from the corner to the pixel, so
//! the corner is the least-squares point p minimising Σ w (gᵀ(q − p))². We
//! iterate that on a window re-sampled (bilinearly) around the current
//! estimate, like OpenCV's cornerSubPix, and keep the final normal matrix and
//! residual to estimate a positional standard deviation for the weight.

/// Grey image as f32, kept at full precision so 16-bit input is not rounded
/// to 8 bits before refinement.
pub struct FloatImage {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Row-major grey levels on a 0..255 scale.
    pub data: Vec<f32>,
}

impl FloatImage {
    fn at(&self, x: usize, y: usize) -> f32 {
        self.data[y * self.width + x]
    }

    /// Bilinear sample with clamp-to-edge, so windows touching the border
    /// never read out of bounds.
    pub fn sample(&self, x: f64, y: f64) -> f64 {
        let xm = (self.width - 1) as f64;
        let ym = (self.height - 1) as f64;
        let x = x.clamp(0.0, xm);
        let y = y.clamp(0.0, ym);
        let (x0, y0) = (x.floor() as usize, y.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(self.width - 1), (y0 + 1).min(self.height - 1));
        let (fx, fy) = (x - x0 as f64, y - y0 as f64);
        let top = self.at(x0, y0) as f64 * (1.0 - fx) + self.at(x1, y0) as f64 * fx;
        let bot = self.at(x0, y1) as f64 * (1.0 - fx) + self.at(x1, y1) as f64 * fx;
        top * (1.0 - fy) + bot * fy
    }

    /// The (2·reach+1)² samples at p + (dx, dy) for integer offsets up to
    /// `reach`, row by row, as [`FloatImage::sample`] gives them. Every sample
    /// shares p's fractional part, so inside the image the bilinear weights are
    /// computed once and the pixels read by index; a window over the border
    /// samples one by one (clamped to the edge).
    pub fn window(&self, p: [f64; 2], reach: isize) -> Vec<f64> {
        let side = (2 * reach + 1) as usize;
        let (x0, y0) = (p[0].floor(), p[1].floor());
        let (left, top) = (x0 as isize - reach, y0 as isize - reach);
        let inside = left >= 0
            && top >= 0
            && left + (side as isize) < self.width as isize
            && top + (side as isize) < self.height as isize;
        if !(inside && p[0].is_finite() && p[1].is_finite()) {
            let mut out = Vec::with_capacity(side * side);
            for dy in -reach..=reach {
                for dx in -reach..=reach {
                    out.push(self.sample(p[0] + dx as f64, p[1] + dy as f64));
                }
            }
            return out;
        }
        let (fx, fy) = (p[0] - x0, p[1] - y0);
        let (left, top) = (left as usize, top as usize);
        let mut out = Vec::with_capacity(side * side);
        for j in 0..side {
            let row = &self.data[(top + j) * self.width + left..];
            let next = &self.data[(top + j + 1) * self.width + left..];
            for i in 0..side {
                let t = row[i] as f64 * (1.0 - fx) + row[i + 1] as f64 * fx;
                let b = next[i] as f64 * (1.0 - fx) + next[i + 1] as f64 * fx;
                out.push(t * (1.0 - fy) + b * fy);
            }
        }
        out
    }

    /// Mean of a few bilinear samples in a disc of radius `r` around (x, y);
    /// used to read a square's brightness robustly against noise.
    pub fn patch_mean(&self, x: f64, y: f64, r: f64) -> f64 {
        let mut acc = 0.0;
        let mut n = 0.0;
        for dy in -2..=2 {
            for dx in -2..=2 {
                acc += self.sample(x + dx as f64 * r / 2.0, y + dy as f64 * r / 2.0);
                n += 1.0;
            }
        }
        acc / n
    }
}

/// Result of refining one corner.
#[derive(Clone, Copy, Debug)]
pub struct Refined {
    /// The refined pixel position.
    pub uv: [f64; 2],
    /// Estimated 1-σ position error (px), largest axis.
    pub sigma: f64,
    /// Point-symmetry misfit in [0, ~2]: Σ(I(p+d) − I(p−d))² / Σ 2(I − Ī)² over
    /// the window. An X-junction (under any locally affine view) is point
    /// symmetric about its centre, so this is ~0 for a clean corner and large
    /// when an occluder, a board edge or clutter enters the window.
    pub asymmetry: f64,
}

const MAX_ITERS: usize = 30;
const EPS: f64 = 1e-3;

/// Refine `start` with a (2·half+1)² window. Returns None when the window has
/// no usable gradient structure (flat or a single edge) or the estimate runs
/// away by more than half a window — the caller then drops the corner rather
/// than report a bad position.
pub fn refine_corner(img: &FloatImage, start: [f64; 2], half: usize) -> Option<Refined> {
    let mut p = start;
    let mut last = None;
    let weights = square_weights(half);
    for _ in 0..MAX_ITERS {
        // The system is in coordinates relative to p (large absolute pixel
        // coordinates would cancel catastrophically in the residual).
        let sys = normal_system(img, p, half, &weights)?;
        let d = sys.solve()?;
        p = [p[0] + d[0], p[1] + d[1]];
        let step = (d[0] * d[0] + d[1] * d[1]).sqrt();
        last = Some((sys, d));
        if step < EPS {
            break;
        }
    }
    let moved = ((p[0] - start[0]).powi(2) + (p[1] - start[1]).powi(2)).sqrt();
    if moved > half as f64 * 0.5 + 0.5 {
        return None;
    }
    let (sys, d) = last?;
    let sigma = sys.sigma_at(d)?;
    Some(Refined {
        uv: p,
        sigma,
        asymmetry: asymmetry(img, p, half),
    })
}

fn asymmetry(img: &FloatImage, p: [f64; 2], half: usize) -> f64 {
    let h = half as isize;
    let side = 2 * h + 1;
    let win = img.window(p, h);
    let at = |dx: isize, dy: isize| win[((h + dy) * side + h + dx) as usize];
    let mut vals = Vec::with_capacity(((2 * h + 1) * (h + 1)) as usize);
    for dy in 0..=h {
        for dx in -h..=h {
            if dy == 0 && dx <= 0 {
                continue;
            }
            vals.push((at(dx, dy), at(-dx, -dy)));
        }
    }
    symmetry_misfit(&vals)
}

/// Σ(a − b)² / Σ((a − m)² + (b − m)²) over pairs of grey levels mirrored
/// through the corner, m their mean.
fn symmetry_misfit(vals: &[(f64, f64)]) -> f64 {
    let n = (2 * vals.len()) as f64;
    let mean = vals.iter().map(|(a, b)| a + b).sum::<f64>() / n;
    let var: f64 = vals
        .iter()
        .map(|(a, b)| (a - mean).powi(2) + (b - mean).powi(2))
        .sum();
    let diff: f64 = vals.iter().map(|(a, b)| (a - b).powi(2)).sum();
    diff / var.max(1e-9)
}

/// Accumulated normal equations A d = b of one iteration (d relative to the
/// window centre), plus the raw sums
/// needed to evaluate the residual at the solution.
struct NormalSystem {
    a: [f64; 3], // symmetric: [a11, a12, a22]
    b: [f64; 2],
    /// Σ w (gᵀq)², to expand the residual Σ w (gᵀ(q − p))² without a second pass.
    c: f64,
    count: f64,
}

impl NormalSystem {
    fn new() -> NormalSystem {
        NormalSystem {
            a: [0.0; 3],
            b: [0.0; 2],
            c: 0.0,
            count: 0.0,
        }
    }

    /// One sample: gradient `g` at offset `q` from the window centre, weight
    /// `w`, standing for `count` pixels.
    fn add(&mut self, g: [f64; 2], q: [f64; 2], w: f64, count: f64) {
        let gq = g[0] * q[0] + g[1] * q[1];
        self.a[0] += w * g[0] * g[0];
        self.a[1] += w * g[0] * g[1];
        self.a[2] += w * g[1] * g[1];
        self.b[0] += w * g[0] * gq;
        self.b[1] += w * g[1] * gq;
        self.c += w * gq * gq;
        self.count += count;
    }

    /// The system when it has any gradient at all.
    fn usable(self) -> Option<NormalSystem> {
        (self.a[0] + self.a[2] > 0.0).then_some(self)
    }

    fn solve(&self) -> Option<[f64; 2]> {
        let [a11, a12, a22] = self.a;
        let det = a11 * a22 - a12 * a12;
        // A near-singular A means a single straight edge: position along it is
        // undetermined.
        if det <= 1e-9 * (a11 + a22).powi(2) || det <= 0.0 {
            return None;
        }
        Some([
            (a22 * self.b[0] - a12 * self.b[1]) / det,
            (a11 * self.b[1] - a12 * self.b[0]) / det,
        ])
    }

    /// Covariance σ̂² A⁻¹ with σ̂² the weighted residual variance; returns the
    /// square root of its largest eigenvalue.
    fn sigma_at(&self, p: [f64; 2]) -> Option<f64> {
        let [a11, a12, a22] = self.a;
        let ap = [a11 * p[0] + a12 * p[1], a12 * p[0] + a22 * p[1]];
        let resid =
            (self.c - 2.0 * (p[0] * self.b[0] + p[1] * self.b[1]) + p[0] * ap[0] + p[1] * ap[1])
                .max(0.0);
        // Rows are sqrt(w)-weighted, so the row variance is the weighted
        // residual over the degrees of freedom.
        let var = resid / (self.count - 2.0).max(1.0);
        let det = a11 * a22 - a12 * a12;
        if det <= 0.0 {
            return None;
        }
        // Eigenvalues of A⁻¹ are 1/λ(A); the largest is 1/λ_min(A).
        let tr = a11 + a22;
        let lmin = 0.5 * (tr - (tr * tr - 4.0 * det).max(0.0).sqrt());
        (lmin > 0.0).then(|| (var / lmin).sqrt())
    }
}

/// The Gaussian weights of a (2·half+1)² window, row by row: the same at every
/// iteration and corner of one window size, so computed once per corner.
fn square_weights(half: usize) -> Vec<f64> {
    let h = half as isize;
    let sigma2 = 2.0 * (half as f64 * 0.5).powi(2).max(1.0);
    (-h..=h)
        .flat_map(|dy| (-h..=h).map(move |dx| (dy, dx)))
        .map(|(dy, dx)| (-((dx * dx + dy * dy) as f64) / sigma2).exp())
        .collect()
}

fn normal_system(
    img: &FloatImage,
    p: [f64; 2],
    half: usize,
    weights: &[f64],
) -> Option<NormalSystem> {
    let h = half as isize;
    let side = (2 * h + 3) as usize;
    // Resample a window one pixel wider than needed, centred on p, so central
    // differences are available for every window pixel.
    let win = img.window(p, h + 1);
    let mut sys = NormalSystem::new();
    let inner = side - 2;
    for j in 1..side - 1 {
        for i in 1..side - 1 {
            let g = [
                0.5 * (win[j * side + i + 1] - win[j * side + i - 1]),
                0.5 * (win[(j + 1) * side + i] - win[(j - 1) * side + i]),
            ];
            let q = [i as f64 - (h + 1) as f64, j as f64 - (h + 1) as f64];
            sys.add(g, q, weights[(j - 1) * inner + i - 1], 1.0);
        }
    }
    sys.usable()
}

/// The local grid frame of a corner: the image vectors from it to its next
/// corner along the board's two axes (px).
pub type Axes = [[f64; 2]; 2];

/// Refine `start` in a window shaped by the local grid: a parallelogram
/// spanning ±`frac` of a cell along each grid vector of `axes`, sampled about
/// one pixel apart along each, Gaussian-weighted in cell units. The gradient
/// condition gᵀ(q − p) = 0 does not change under an affine map, so on a
/// compressed or sheared junction near a fisheye's rim this window covers the
/// same part of the four squares as a square window does on a square-on
/// board: it never reaches the neighbouring junctions along the short
/// diagonal, which a square window sized to the shortest spacing still does.
/// None as for [`refine_corner`].
pub fn refine_affine(img: &FloatImage, start: [f64; 2], axes: Axes, frac: f64) -> Option<Refined> {
    refine_in(img, start, AffineWindow::new(axes, frac, &|_, _| true)?)
}

/// [`refine_affine`] on the part of the window where `keep(a, b)` holds, (a, b)
/// the offset in cell units along the two grid vectors. `keep` must be point
/// symmetric (keep(a, b) = keep(−a, −b)) so that the symmetry check still
/// compares mirrored samples: a ChArUco board uses it to reach along the four
/// edges through a junction while leaving out its markers.
pub fn refine_masked(
    img: &FloatImage,
    start: [f64; 2],
    axes: Axes,
    frac: f64,
    keep: &dyn Fn(f64, f64) -> bool,
) -> Option<Refined> {
    refine_in(img, start, AffineWindow::new(axes, frac, keep)?)
}

fn refine_in(img: &FloatImage, start: [f64; 2], win: AffineWindow) -> Option<Refined> {
    let mut p = start;
    let mut last = None;
    for _ in 0..MAX_ITERS {
        let sys = win.normal_system(img, p)?;
        let d = sys.solve()?;
        p = [p[0] + d[0], p[1] + d[1]];
        last = Some((sys, d));
        if d[0].hypot(d[1]) < EPS {
            break;
        }
    }
    // Half the window's reach along its shorter axis, as for the square window.
    if (p[0] - start[0]).hypot(p[1] - start[1]) > 0.5 * win.reach() + 0.5 {
        return None;
    }
    let (sys, d) = last?;
    Some(Refined {
        uv: p,
        sigma: sys.sigma_at(d)?,
        asymmetry: win.asymmetry(img, p),
    })
}

/// The sample grid of [`refine_affine`]: offsets a·e_u + b·e_v for (a, b) on
/// a grid over [−frac, frac]², with their Gaussian weights.
struct AffineWindow {
    /// (offset from the corner in px, weight).
    samples: Vec<([f64; 2], f64)>,
    /// Image area (px²) each sample stands for, so sums are per pixel and the
    /// σ estimate does not shrink with denser sampling.
    area: f64,
    axes: Axes,
    frac: f64,
}

impl AffineWindow {
    fn new(axes: Axes, frac: f64, keep: &dyn Fn(f64, f64) -> bool) -> Option<AffineWindow> {
        let [eu, ev] = axes;
        let (lu, lv) = (eu[0].hypot(eu[1]), ev[0].hypot(ev[1]));
        let det = (eu[0] * ev[1] - eu[1] * ev[0]).abs();
        if !(lu.is_finite() && lv.is_finite()) || det < 1.0 || frac <= 0.0 {
            return None;
        }
        // About one sample per pixel along each grid vector.
        let (nu, nv) = ((frac * lu).ceil().max(2.0), (frac * lv).ceil().max(2.0));
        let (hu, hv) = (frac / nu, frac / nv);
        let s2 = 2.0 * (0.5 * frac).powi(2);
        let mut samples = Vec::new();
        for j in -(nv as i32)..=nv as i32 {
            for i in -(nu as i32)..=nu as i32 {
                let (a, b) = (i as f64 * hu, j as f64 * hv);
                if !keep(a, b) {
                    continue;
                }
                let q = [a * eu[0] + b * ev[0], a * eu[1] + b * ev[1]];
                samples.push((q, (-(a * a + b * b) / s2).exp()));
            }
        }
        Some(AffineWindow {
            samples,
            area: det * hu * hv,
            axes,
            frac,
        })
    }

    /// The window's smallest distance (px) from its centre to its border.
    fn reach(&self) -> f64 {
        let [eu, ev] = self.axes;
        let det = (eu[0] * ev[1] - eu[1] * ev[0]).abs();
        // Distance between the parallelogram's opposite sides, halved.
        let (lu, lv) = (eu[0].hypot(eu[1]), ev[0].hypot(ev[1]));
        self.frac * det / lu.max(lv)
    }

    fn normal_system(&self, img: &FloatImage, p: [f64; 2]) -> Option<NormalSystem> {
        let mut sys = NormalSystem::new();
        for &(q, w) in &self.samples {
            let (x, y) = (p[0] + q[0], p[1] + q[1]);
            let g = [
                0.5 * (img.sample(x + 1.0, y) - img.sample(x - 1.0, y)),
                0.5 * (img.sample(x, y + 1.0) - img.sample(x, y - 1.0)),
            ];
            sys.add(g, q, w * self.area, self.area);
        }
        sys.usable()
    }

    /// [`asymmetry`] over this window: pairs of samples mirrored through `p`.
    fn asymmetry(&self, img: &FloatImage, p: [f64; 2]) -> f64 {
        let half = &self.samples[..self.samples.len() / 2];
        let vals: Vec<(f64, f64)> = half
            .iter()
            .map(|&(q, _)| {
                (
                    img.sample(p[0] + q[0], p[1] + q[1]),
                    img.sample(p[0] - q[0], p[1] - q[1]),
                )
            })
            .collect();
        symmetry_misfit(&vals)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_window_is_its_samples_inside_and_across_the_border() {
        let img = FloatImage {
            width: 23,
            height: 17,
            data: (0..23 * 17)
                .map(|k| ((k * 37) % 101) as f32 * 1.7)
                .collect(),
        };
        for p in [
            [11.3, 8.6],
            [2.2, 2.9],
            [0.4, 15.7],
            [21.9, 1.1],
            [-3.0, 30.5],
        ] {
            let win = img.window(p, 2);
            let mut k = 0;
            for dy in -2..=2 {
                for dx in -2..=2 {
                    let s = img.sample(p[0] + dx as f64, p[1] + dy as f64);
                    assert!(
                        (win[k] - s).abs() < 1e-9,
                        "{p:?} ({dx}, {dy}): {} vs {s}",
                        win[k]
                    );
                    k += 1;
                }
            }
        }
    }
}
