//! The viewport camera: orbit, pan and zoom about a target, with a fixed up axis. It holds
//! while time moves; only the mouse and "reset view" change it.

use slosh_mls::Camera;

/// Sub, add, scale, dot, cross and normalise on 3-vectors.
fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|i| a[i] - b[i])
}
fn add(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|i| a[i] + b[i])
}
fn scale(a: [f64; 3], s: f64) -> [f64; 3] {
    a.map(|v| v * s)
}
fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn normalize(a: [f64; 3]) -> [f64; 3] {
    let l = dot(a, a).sqrt();
    if l > 0.0 { scale(a, 1.0 / l) } else { a }
}

/// `v` rotated by `angle` radians about the unit `axis` (Rodrigues).
fn rotate(v: [f64; 3], axis: [f64; 3], angle: f64) -> [f64; 3] {
    let (s, c) = angle.sin_cos();
    let k = cross(axis, v);
    let along = scale(axis, dot(axis, v) * (1.0 - c));
    add(add(scale(v, c), scale(k, s)), along)
}

/// Radians of orbit per pixel dragged.
const ORBIT_PER_PIXEL: f64 = 0.008;
/// The eye never comes closer than this to the up axis through the target (radians).
const POLE_MARGIN: f64 = 0.02;

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OrbitCamera {
    pub eye: [f64; 3],
    pub target: [f64; 3],
    /// A unit axis.
    pub up: [f64; 3],
    pub fov_y: f64,
}

impl OrbitCamera {
    /// The framing camera of `bounds` with `up` up (`slosh render`'s camera for z up).
    /// `bounds` filling a viewport of `size` pixels ([`Camera::filling`]: `slosh render`'s
    /// view, as near as the box allows).
    pub fn framing(
        bounds: &[[f64; 3]; 2],
        fov_y: f64,
        up: [f64; 3],
        size: (u32, u32),
    ) -> OrbitCamera {
        let c = Camera::filling(bounds, fov_y, size.0, size.1, up);
        OrbitCamera {
            eye: c.eye,
            target: c.target,
            up: c.up,
            fov_y,
        }
    }

    pub fn camera(&self, width: u32, height: u32) -> Camera {
        Camera {
            eye: self.eye,
            target: self.target,
            up: self.up,
            fov_y: self.fov_y,
            width,
            height,
        }
    }

    /// Orbits by a drag of (dx, dy) pixels: about the up axis, then over the top.
    pub fn orbit(&mut self, dx: f64, dy: f64) {
        let offset = sub(self.eye, self.target);
        let turned = rotate(offset, self.up, -dx * ORBIT_PER_PIXEL);
        let right = normalize(cross(turned, self.up));
        let r = dot(turned, turned).sqrt();
        // Pitch, kept off the poles so `up` stays a valid up vector.
        let polar = (dot(turned, self.up) / r.max(1e-300))
            .clamp(-1.0, 1.0)
            .acos();
        let wanted =
            (polar + dy * ORBIT_PER_PIXEL).clamp(POLE_MARGIN, std::f64::consts::PI - POLE_MARGIN);
        let tilted = rotate(turned, right, wanted - polar);
        self.eye = add(self.target, tilted);
    }

    /// Pans by (dx, dy) pixels of a viewport `height` pixels high: the target and eye move
    /// together in the image plane, as far as the pointer moved at the target's depth.
    pub fn pan(&mut self, dx: f64, dy: f64, height: f64) {
        let offset = sub(self.eye, self.target);
        let distance = dot(offset, offset).sqrt();
        let per_pixel = 2.0 * distance * (self.fov_y.to_radians() * 0.5).tan() / height.max(1.0);
        let forward = normalize(scale(offset, -1.0));
        let right = normalize(cross(forward, self.up));
        let up = cross(right, forward);
        let shift = add(scale(right, -dx * per_pixel), scale(up, dy * per_pixel));
        self.eye = add(self.eye, shift);
        self.target = add(self.target, shift);
    }

    /// Moves the eye towards the target by `factor` (< 1 closer, > 1 farther).
    pub fn zoom(&mut self, factor: f64) {
        if factor.is_finite() && factor > 0.0 {
            let offset = sub(self.eye, self.target);
            self.eye = add(self.target, scale(offset, factor.clamp(0.05, 20.0)));
        }
    }

    pub fn distance(&self) -> f64 {
        let o = sub(self.eye, self.target);
        dot(o, o).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const BOUNDS: [[f64; 3]; 2] = [[-1.0, -2.0, 0.0], [1.0, 2.0, 1.0]];

    #[test]
    fn the_initial_view_fills_the_viewport_from_the_render_framings_direction() {
        let c = OrbitCamera::framing(&BOUNDS, 40.0, [0.0, 0.0, 1.0], (64, 48)).camera(64, 48);
        assert_eq!(c, Camera::filling(&BOUNDS, 40.0, 64, 48, [0.0, 0.0, 1.0]));
    }

    #[test]
    fn orbiting_keeps_distance_and_target_and_stays_off_the_pole() {
        let mut c = OrbitCamera::framing(&BOUNDS, 40.0, [0.0, 1.0, 0.0], (64, 48));
        let (d, t) = (c.distance(), c.target);
        c.orbit(120.0, -35.0);
        assert!((c.distance() - d).abs() < 1e-9 * d);
        assert_eq!(c.target, t);
        for _ in 0..100 {
            c.orbit(0.0, -500.0);
        }
        let o = sub(c.eye, c.target);
        let polar = (dot(o, c.up) / dot(o, o).sqrt()).acos();
        assert!(polar >= POLE_MARGIN - 1e-9, "{polar}");
        // A full turn about up comes back.
        let before = c.eye;
        c.orbit(2.0 * std::f64::consts::PI / ORBIT_PER_PIXEL, 0.0);
        assert!(before.iter().zip(c.eye).all(|(a, b)| (a - b).abs() < 1e-9));
    }

    #[test]
    fn pan_moves_eye_and_target_together_and_zoom_scales_distance() {
        let mut c = OrbitCamera::framing(&BOUNDS, 40.0, [0.0, 0.0, 1.0], (64, 48));
        let (d, offset) = (c.distance(), sub(c.eye, c.target));
        c.pan(30.0, -12.0, 480.0);
        assert!(
            sub(c.eye, c.target)
                .iter()
                .zip(offset)
                .all(|(a, b)| (a - b).abs() < 1e-12)
        );
        c.zoom(0.5);
        assert!((c.distance() - 0.5 * d).abs() < 1e-12);
        c.zoom(f64::NAN);
        assert!((c.distance() - 0.5 * d).abs() < 1e-12);
    }
}
