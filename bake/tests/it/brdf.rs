//! The reflectance models: reciprocity and energy conservation.

use glam::DVec3;
use ltm_bake::material::Material;
use ltm_bake::scene::MaterialDesc;
use std::f64::consts::PI;

fn glossy(albedo: f64, specular: f64, roughness: f64) -> Material {
    Material::new(&MaterialDesc::Glossy {
        albedo: [albedo; 3],
        specular: [specular, 0.5 * specular, 1.0],
        roughness,
    })
}

fn dir(mu: f64, phi: f64) -> DVec3 {
    let s = (1.0 - mu * mu).max(0.0).sqrt();
    DVec3::new(s * phi.cos(), mu, s * phi.sin())
}

/// ∫ f_r(ω_i, ω_o) cos θ_i dω_i per channel, by a midpoint rule in (μ, φ)
/// (dω = dμ dφ), fine enough to resolve the lobes tested.
fn albedo(m: &Material, wo: DVec3) -> [f64; 3] {
    let (nm, np) = (1200, 600);
    let n = DVec3::Y;
    let mut e = [0.0; 3];
    for a in 0..nm {
        let mu = (a as f64 + 0.5) / nm as f64;
        for b in 0..np {
            let phi = 2.0 * PI * (b as f64 + 0.5) / np as f64;
            let f = m.eval(n, dir(mu, phi), wo);
            for c in 0..3 {
                e[c] += f[c] * mu;
            }
        }
    }
    e.map(|v| v * 2.0 * PI / (nm * np) as f64)
}

#[test]
fn reciprocity() {
    let mut k = 1u64;
    let mut rnd = || {
        k = ltm_bake::sampling::mix64(k);
        (k >> 11) as f64 / (1u64 << 53) as f64
    };
    for m in [
        glossy(0.8, 0.04, 0.15),
        glossy(0.3, 0.9, 0.6),
        glossy(1.0, 0.2, 1.0),
    ] {
        for _ in 0..500 {
            let wi = dir(rnd(), 2.0 * PI * rnd());
            let wo = dir(rnd().max(1e-3), 2.0 * PI * rnd());
            let (a, b) = (m.eval(DVec3::Y, wi, wo), m.eval(DVec3::Y, wo, wi));
            for c in 0..3 {
                assert!(a[c].is_finite() && a[c] >= 0.0);
                assert!(
                    (a[c] - b[c]).abs() <= 1e-9 * a[c].max(1.0),
                    "{a:?} vs {b:?}"
                );
            }
        }
    }
}

#[test]
fn lambert_white_furnace() {
    let m = Material::new(&MaterialDesc::Lambert {
        albedo: [1.0, 0.5, 0.0],
    });
    let e = albedo(&m, dir(0.6, 0.3));
    assert!(
        (e[0] - 1.0).abs() < 1e-4 && (e[1] - 0.5).abs() < 1e-4 && e[2] == 0.0,
        "{e:?}"
    );
}

/// Lambert + specular with Fresnel never reflects more than it receives;
/// with a white base it reflects everything (the base takes exactly what
/// the lobe does not).
#[test]
fn glossy_white_furnace() {
    for roughness in [0.25, 0.5, 1.0] {
        for specular in [0.04, 0.5, 1.0] {
            for mu in [1.0, 0.7, 0.3, 0.1] {
                let wo = dir(mu, 0.0);
                let white = albedo(&glossy(1.0, specular, roughness), wo);
                let black = albedo(&glossy(0.0, specular, roughness), wo);
                for c in 0..3 {
                    let tag = format!("α {roughness}, F0 {specular}, μ {mu}, channel {c}");
                    assert!(white[c] <= 1.0 + 4e-3, "{tag}: {white:?}");
                    assert!(white[c] >= 0.99, "{tag}: {white:?}");
                    assert!(
                        black[c] <= white[c] + 1e-9 && black[c] > 0.0,
                        "{tag}: {black:?}"
                    );
                }
            }
        }
    }
    // A smooth white lobe (F = 1) at normal incidence reflects nearly all;
    // single-scattering GGX loses only what its tail sends below the
    // horizon (about α²/(1 + α²)) and what masking removes.
    let e = albedo(&glossy(0.0, 1.0, 0.1), dir(1.0, 0.0));
    assert!(e[2] > 0.98 && e[2] <= 1.0, "{e:?}");
}

#[test]
fn below_the_horizon_is_black() {
    let m = glossy(0.5, 0.04, 0.3);
    assert_eq!(m.eval(DVec3::Y, dir(-0.2, 0.0), dir(0.5, 1.0)), [0.0; 3]);
}
