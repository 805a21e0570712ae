//! The closed-form derivatives against central differences of the projection,
//! for every lens model, over the whole image, close to the axis and close to
//! the edge of the fisheye models' domains.
use super::*;
use crate::model::lens::LensModel;

/// Relative step of the central differences (of the parameter, or of |x_c|).
const STEP: f64 = 1e-6;

/// The camera-frame points to test: rays through a 9 × 7 grid of pixels (the
/// image's edges and corners included) at two depths, rays just off the axis,
/// and rays at the given angles off it (fisheye models' wide rays).
fn points(k: &Intrinsics, wide: &[f64]) -> Vec<Vector3<f64>> {
    let (w, h) = (1936.0, 1216.0);
    let mut out = vec![Vector3::new(0.0, 0.0, 1.0), Vector3::new(1e-9, -2e-9, 0.7)];
    for gy in 0..7 {
        for gx in 0..9 {
            let px = Vector2::new(gx as f64 * (w - 1.0) / 8.0, gy as f64 * (h - 1.0) / 6.0);
            if let Some(ray) = k.unproject(&px) {
                out.extend([ray * 0.3, ray * 2.5]);
            }
        }
    }
    for &angle in wide {
        let (s, c) = angle.sin_cos();
        out.push(Vector3::new(0.8 * s, -0.6 * s, c));
    }
    out
}

/// Asserts that `got` is within a relative 1e-6 of the central difference of
/// `f` (a pixel) in one coordinate of `at`, moved by `h`.
fn check(
    what: &str,
    got: Vector2<f64>,
    h: f64,
    mut at: impl FnMut(f64) -> Option<Vector2<f64>>,
) -> f64 {
    let (plus, minus) = (at(h).expect(what), at(-h).expect(what));
    let cd = (plus - minus) / (2.0 * h);
    let scale = got.norm().max(cd.norm()).max(1.0);
    let err = (got - cd).norm() / scale;
    assert!(
        err < 1e-6,
        "{what}: {got} against {cd} (relative {err:.1e})"
    );
    err
}

fn check_model(k: &Intrinsics, wide: &[f64]) -> f64 {
    let mut worst = 0.0f64;
    let pts = points(k, wide);
    assert!(pts.len() > 40, "{k:?}: too few points");
    for xc in pts {
        let Some(d) = k.project_with_derivatives(&xc) else {
            assert!(k.project(&xc).is_none(), "{k:?} {xc}");
            continue;
        };
        assert_eq!(Some(d.uv), k.project(&xc), "{k:?} {xc}: the same pixel");
        for (i, &p) in k.params().iter().enumerate() {
            let what = format!("{:?} at {xc}: ∂/∂{}", k.model(), k.model().param_names()[i]);
            let got = Vector2::new(d.d_params[0][i], d.d_params[1][i]);
            let h = STEP * p.abs().max(1.0);
            worst = worst.max(check(&what, got, h, |step| {
                let mut q = *k;
                q.params_mut()[i] = p + step;
                q.project(&xc)
            }));
        }
        for a in 0..3 {
            let what = format!("{:?} at {xc}: ∂/∂x_c[{a}]", k.model());
            let h = STEP * xc.norm();
            worst = worst.max(check(&what, d.d_point.column(a).into(), h, |step| {
                let mut q = xc;
                q[a] += step;
                k.project(&q)
            }));
        }
    }
    worst
}

#[test]
fn closed_form_derivatives_are_the_central_differences() {
    for model in LensModel::ALL {
        let k = Intrinsics::from_params(model, model.info().synthetic).unwrap();
        // The fisheyes' wide rays: kb4's synthetic corners lie about 95° off
        // axis; ds's domain ends where z = −w2 |x_c| (about 110° for its
        // synthetic ξ, α), the last ray 1e-4 rad inside it.
        let wide = match model {
            LensModel::Kb4 => vec![1.4, 1.66, 2.0, 2.6],
            LensModel::DoubleSphere => {
                let edge = ds_edge(k.params());
                vec![1.4, edge - 0.05, edge - 1e-3, edge - 1e-4]
            }
            _ => vec![],
        };
        let worst = check_model(&k, &wide);
        eprintln!("{model}: worst relative difference {worst:.1e}");
    }
}

/// The angle off the axis where the double sphere's domain ends: cos θ = −w2.
fn ds_edge(p: &[f64]) -> f64 {
    let (xi, alpha) = (p[4], p[5]);
    let w1 = if alpha <= 0.5 {
        alpha / (1.0 - alpha)
    } else {
        (1.0 - alpha) / alpha
    };
    let w2 = (w1 + xi) / (2.0 * w1 * xi + xi * xi + 1.0).sqrt();
    (-w2).acos()
}

#[test]
fn rays_beyond_the_domain_have_no_derivatives() {
    for model in LensModel::ALL {
        let k = Intrinsics::from_params(model, model.info().synthetic).unwrap();
        let behind = Vector3::new(0.0, 0.0, -1.0);
        assert_eq!(k.project_with_derivatives(&behind), None, "{model}");
    }
    let k = Intrinsics::from_params(
        LensModel::DoubleSphere,
        LensModel::DoubleSphere.info().synthetic,
    )
    .unwrap();
    let beyond = ds_edge(k.params()) + 1e-3;
    let xc = Vector3::new(beyond.sin(), 0.0, beyond.cos());
    assert_eq!(k.project_with_derivatives(&xc), None);
    assert_eq!(k.project(&xc), None);
}
