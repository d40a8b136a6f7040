//! The recovered eye against the cameras the records were made with.

use super::*;
use crate::surface::SurfacePoint;
use glam::DVec3;

/// A pinhole camera: rays through pixel centres, as the bake casts them.
struct Pinhole {
    eye: DVec3,
    forward: DVec3,
    right: DVec3,
    up: DVec3,
    tan_half: f64,
    size: (usize, usize),
}

impl Pinhole {
    fn new(eye: DVec3, target: DVec3, fov_deg: f64, size: (usize, usize)) -> Pinhole {
        let forward = (target - eye).normalize();
        let right = forward.cross(DVec3::Y).normalize();
        Pinhole {
            eye,
            forward,
            right,
            up: right.cross(forward),
            tan_half: (fov_deg.to_radians() / 2.0).tan(),
            size,
        }
    }

    fn ray(&self, k: usize) -> DVec3 {
        let (w, h) = (self.size.0 as f64, self.size.1 as f64);
        let (x, y) = (
            (k % self.size.0) as f64 + 0.5,
            (k / self.size.0) as f64 + 0.5,
        );
        let sx = (2.0 * x / w - 1.0) * self.tan_half * w / h;
        let sy = (1.0 - 2.0 * y / h) * self.tan_half;
        (self.forward + sx * self.right + sy * self.up).normalize()
    }
}

/// A scene of spheres (centre, radius) over an optional ground plane
/// `y = 0`: the first hit of each ray, stored as `f32` records.
fn records(cam: &Pinhole, spheres: &[(DVec3, f64)], ground: bool) -> Surface {
    let points = (0..cam.size.0 * cam.size.1)
        .map(|k| {
            let d = cam.ray(k);
            let mut best: Option<(f64, DVec3)> = None;
            for &(c, r) in spheres {
                let oc = cam.eye - c;
                let b = oc.dot(d);
                let disc = b * b - (oc.length_squared() - r * r);
                let t = -b - disc.max(0.0).sqrt();
                if disc >= 0.0 && t > 0.0 && best.is_none_or(|(bt, _)| t < bt) {
                    best = Some((t, (cam.eye + t * d - c) / r));
                }
            }
            let t_ground = -cam.eye.y / d.y;
            if ground && t_ground > 0.0 && best.is_none_or(|(bt, _)| t_ground < bt) {
                best = Some((t_ground, DVec3::Y));
            }
            match best {
                Some((t, n)) => SurfacePoint::new(
                    (cam.eye + t * d).as_vec3().to_array(),
                    n.as_vec3().to_array(),
                ),
                None => SurfacePoint::INVALID,
            }
        })
        .collect();
    Surface::new(points).unwrap()
}

fn relative_eye_error(cam: &Pinhole, fit: &ImageCamera) -> f64 {
    (DVec3::from_array(fit.eye()) - cam.eye).length() / cam.eye.length()
}

#[test]
fn the_eye_of_pinhole_cameras_is_recovered() {
    let cases = [
        // An object on a floor, 96 × 72.
        (
            DVec3::new(0.3, 1.2, 3.0),
            DVec3::new(0.0, 0.4, 0.0),
            40.0,
            (96, 72),
            1.0,
            true,
        ),
        // Odd sizes, a wide lens, off-centre.
        (
            DVec3::new(-2.0, 0.7, 1.1),
            DVec3::new(0.2, 0.3, -0.1),
            75.0,
            (33, 17),
            1.0,
            true,
        ),
        // A narrow lens far away: depth varies little.
        (
            DVec3::new(4.0, 3.0, 20.0),
            DVec3::new(0.0, 0.5, 0.0),
            6.0,
            (64, 64),
            1.0,
            false,
        ),
        // Extreme scales: a scene in kilometres and one in millimetres.
        (
            DVec3::new(3e3, 1.5e3, 4e3),
            DVec3::new(0.0, 400.0, 0.0),
            30.0,
            (48, 40),
            1e3,
            true,
        ),
        (
            DVec3::new(3e-3, 2e-3, 5e-3),
            DVec3::new(0.0, 4e-4, 0.0),
            50.0,
            (40, 48),
            1e-3,
            true,
        ),
        // Scales f32 still holds, far from 1.
        (
            DVec3::new(3e15, 1.5e15, 4e15),
            DVec3::new(0.0, 4e14, 0.0),
            30.0,
            (32, 24),
            1e15,
            true,
        ),
        (
            DVec3::new(3e-20, 1.5e-20, 4e-20),
            DVec3::new(0.0, 4e-21, 0.0),
            30.0,
            (32, 24),
            1e-20,
            true,
        ),
    ];
    for (eye, target, fov, size, scale, ground) in cases {
        let cam = Pinhole::new(eye, target, fov, size);
        let spheres = [
            (DVec3::new(0.0, 0.5, 0.0) * scale, 0.5 * scale),
            (DVec3::new(0.9, 0.25, 0.4) * scale, 0.25 * scale),
        ];
        let fit = ImageCamera::recover(&records(&cam, &spheres, ground), size.0).unwrap();
        let err = relative_eye_error(&cam, &fit);
        assert!(
            err < 1e-4,
            "eye {eye} recovered as {:?} ({err:e})",
            fit.eye()
        );
        assert!(fit.max_residual_px() < 0.01, "{}", fit.max_residual_px());
        assert!(fit.points() >= MIN_CAMERA_POINTS);
    }
}

#[test]
fn records_that_do_not_fix_the_eye_are_refused() {
    let cam = Pinhole::new(DVec3::new(0.3, 1.2, 3.0), DVec3::ZERO, 40.0, (64, 48));
    let err = |s: &Surface| ImageCamera::recover(s, 64).unwrap_err().to_string();
    // A floor alone: every record on one plane.
    let floor = records(&cam, &[], true);
    assert!(err(&floor).contains("on one plane"), "{}", err(&floor));
    // Nothing hit, and too few points hit.
    let empty = records(&cam, &[], false);
    assert!(
        err(&empty).contains("0 valid surface records"),
        "{}",
        err(&empty)
    );
    let mut few = empty.points().to_vec();
    for k in [0, 100, 1000, 2000, 3000] {
        few[k] = floor.points()[k + 40];
    }
    let few = Surface::new(few).unwrap();
    assert!(err(&few).contains("5 valid"), "{}", err(&few));
    // Every record at one point.
    let same = Surface::new(vec![
        SurfacePoint::new([1.0, 2.0, 3.0], [0.0, 0.0, 1.0]);
        64 * 48
    ])
    .unwrap();
    assert!(
        err(&same).contains("recovering the camera"),
        "{}",
        err(&same)
    );
    // A width that does not divide the rows.
    let msg = ImageCamera::recover(&floor, 100).unwrap_err().to_string();
    assert!(msg.contains("image width = 100"), "{msg}");
    assert!(ImageCamera::recover(&floor, 0).is_err());
}

#[test]
fn records_of_no_single_pinhole_are_refused() {
    let cam = Pinhole::new(
        DVec3::new(0.3, 1.2, 3.0),
        DVec3::new(0.0, 0.4, 0.0),
        40.0,
        (64, 48),
    );
    let scene = records(&cam, &[(DVec3::new(0.0, 0.5, 0.0), 0.5)], true);
    // Rows stored in another order (the width is wrong by one transpose).
    let msg = ImageCamera::recover(&scene, 48).unwrap_err().to_string();
    assert!(msg.contains("no single pinhole"), "{msg}");
    // One record moved along the floor, off its ray.
    let mut moved = scene.points().to_vec();
    let k = moved.iter().rposition(|p| p.valid).unwrap();
    moved[k].position[0] += 0.05;
    let msg = ImageCamera::recover(&Surface::new(moved).unwrap(), 64)
        .unwrap_err()
        .to_string();
    assert!(msg.contains("no single pinhole"), "{msg}");
    // Parallel rays (an orthographic camera) have no centre.
    let ortho: Vec<_> = (0..64 * 48)
        .map(|k| {
            let (x, y) = ((k % 64) as f32 / 32.0 - 1.0, (k / 64) as f32 / 24.0 - 1.0);
            let z = 0.3 * (3.0 * x).sin() + 0.2 * y * y;
            SurfacePoint::new([x, y, z], [0.0, 0.0, 1.0])
        })
        .collect();
    let msg = ImageCamera::recover(&Surface::new(ortho).unwrap(), 64)
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("no centre") || msg.contains("not a pinhole camera"),
        "{msg}"
    );
}
