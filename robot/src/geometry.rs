//! Planar geometry shared by every model: 2-D vectors and rotations about z.

/// A 2-D vector in millimetres (or unitless for directions).
pub type Vec2 = [f64; 2];

/// R(a) v: rotates `v` counter-clockwise by `a` radians about z.
#[inline]
pub fn rot(a: f64, v: Vec2) -> Vec2 {
    let (s, c) = a.sin_cos();
    [c * v[0] - s * v[1], s * v[0] + c * v[1]]
}

/// v rotated by +90 degrees.
#[inline]
pub fn perp(v: Vec2) -> Vec2 {
    [-v[1], v[0]]
}

/// a + b
#[inline]
pub fn add(a: Vec2, b: Vec2) -> Vec2 {
    [a[0] + b[0], a[1] + b[1]]
}

/// a - b
#[inline]
pub fn sub(a: Vec2, b: Vec2) -> Vec2 {
    [a[0] - b[0], a[1] - b[1]]
}

/// s v
#[inline]
pub fn scale(s: f64, v: Vec2) -> Vec2 {
    [s * v[0], s * v[1]]
}

/// Dot product.
#[inline]
pub fn dot(a: Vec2, b: Vec2) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

/// z-component of the cross product a x b.
#[inline]
pub fn cross(a: Vec2, b: Vec2) -> f64 {
    a[0] * b[1] - a[1] * b[0]
}

/// Euclidean norm.
#[inline]
pub fn norm(v: Vec2) -> f64 {
    v[0].hypot(v[1])
}

/// Signed angle (radians, in (-pi, pi]) that turns direction `from` onto direction `to`.
#[inline]
pub fn signed_angle(from: Vec2, to: Vec2) -> f64 {
    cross(from, to).atan2(dot(from, to))
}

/// Wraps an angle to (-pi, pi].
#[inline]
pub fn wrap_angle(a: f64) -> f64 {
    let two_pi = std::f64::consts::TAU;
    let mut r = a % two_pi;
    if r <= -std::f64::consts::PI {
        r += two_pi;
    } else if r > std::f64::consts::PI {
        r -= two_pi;
    }
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotation_is_counter_clockwise() {
        let v = rot(std::f64::consts::FRAC_PI_2, [1.0, 0.0]);
        assert!((v[0]).abs() < 1e-15 && (v[1] - 1.0).abs() < 1e-15);
    }

    #[test]
    fn signed_angle_sign() {
        assert!(signed_angle([1.0, 0.0], [0.0, 1.0]) > 0.0);
        assert!(signed_angle([1.0, 0.0], [0.0, -1.0]) < 0.0);
        assert!((wrap_angle(3.0 * std::f64::consts::PI) - std::f64::consts::PI).abs() < 1e-12);
    }
}
