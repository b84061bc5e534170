//! Registration: the rigid transform from the capture frame to the robot base frame, fitted
//! to the base markers B_i measured in the capture frame (3-D) and the base points of the
//! robot configuration (in the robot's plane, z = 0), by least squares (Kabsch: SVD of the
//! cross-covariance, proper rotation). `p_robot = R p_capture + t`.

use crate::frame::{Body, Frame};
use crate::params::Parameters;
use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Default largest residual of a base marker accepted by a registration, mm.
pub const DEFAULT_MAX_RESIDUAL_MM: f64 = 1.0;

/// Marker labels the bridge looks for.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct MarkerLabels {
    /// Labels of the base points B_1..B_3.
    pub base: [String; 3],
    /// Labels of the passive joints M_1..M_3.
    pub joints: [String; 3],
}

impl Default for MarkerLabels {
    fn default() -> Self {
        Self {
            base: ["B1".into(), "B2".into(), "B3".into()],
            joints: ["M1".into(), "M2".into(), "M3".into()],
        }
    }
}

/// Why a registration was refused or cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum RegistrationError {
    /// A base marker is not among the server's labels.
    #[error("base marker {0:?} is not a labelled marker of the server (labels: {1})")]
    UnknownLabel(String, String),
    /// A base marker was not seen often enough.
    #[error("base marker {label:?} is missing: seen in {seen} of {frames} frames")]
    Missing {
        /// Its label.
        label: String,
        /// Frames it was measured in.
        seen: usize,
        /// Frames collected.
        frames: usize,
    },
    /// The fit is worse than allowed.
    #[error(
        "registration refused: residual of {label} is {residual_mm:.3} mm, above the \
         {max_mm:.3} mm allowed (residuals: {all}); check the labels, the markers and the robot \
         configuration's base points"
    )]
    Residual {
        /// The worst marker.
        label: String,
        /// Its residual, mm.
        residual_mm: f64,
        /// The bound, mm.
        max_mm: f64,
        /// Every marker's residual.
        all: String,
    },
    /// The base markers are (nearly) collinear.
    #[error("the base markers are collinear: no unique transform")]
    Degenerate,
    /// File I/O.
    #[error("registration file {path}: {message}")]
    File {
        /// The file.
        path: String,
        /// What went wrong.
        message: String,
    },
}

/// One marker's fit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MarkerResidual {
    /// Label.
    pub label: String,
    /// Distance between the transformed measurement and the configured point, mm.
    pub residual_mm: f64,
}

/// The capture-to-robot transform.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Registration {
    /// Rotation, row-major (capture -> robot).
    pub rotation: [[f64; 3]; 3],
    /// Translation, mm.
    pub translation_mm: [f64; 3],
    /// Per-marker residuals of the fit, mm (information).
    #[serde(default)]
    pub residuals: Vec<MarkerResidual>,
    /// Frames averaged for the fit (information).
    #[serde(default)]
    pub frames: usize,
}

impl Default for Registration {
    fn default() -> Self {
        Self::identity()
    }
}

impl Registration {
    /// The identity (capture frame = robot frame).
    pub fn identity() -> Self {
        Self {
            rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            translation_mm: [0.0; 3],
            residuals: Vec::new(),
            frames: 0,
        }
    }

    fn r(&self) -> Matrix3<f64> {
        Matrix3::from_fn(|i, j| self.rotation[i][j])
    }

    /// Least-squares rigid fit of capture points onto robot-plane points (z = 0).
    pub fn fit(
        labels: &[String],
        capture: &[[f64; 3]],
        robot: &[[f64; 2]],
    ) -> Result<Registration, RegistrationError> {
        let n = capture.len().min(robot.len());
        if n < 3 {
            return Err(RegistrationError::Degenerate);
        }
        let p: Vec<Vector3<f64>> = capture[..n].iter().map(|c| Vector3::from(*c)).collect();
        let q: Vec<Vector3<f64>> = robot[..n]
            .iter()
            .map(|r| Vector3::new(r[0], r[1], 0.0))
            .collect();
        let pc = p.iter().sum::<Vector3<f64>>() / n as f64;
        let qc = q.iter().sum::<Vector3<f64>>() / n as f64;
        let mut h = Matrix3::zeros();
        for (a, b) in p.iter().zip(&q) {
            h += (a - pc) * (b - qc).transpose();
        }
        let svd = h.svd(true, true);
        let (Some(u), Some(vt)) = (svd.u, svd.v_t) else {
            return Err(RegistrationError::Degenerate);
        };
        let mut s = svd.singular_values;
        s.as_mut_slice()
            .sort_by(|a, b| b.partial_cmp(a).unwrap_or(std::cmp::Ordering::Equal));
        if s[1] < 1e-6 * s[0].max(1e-12) {
            return Err(RegistrationError::Degenerate);
        }
        let v = vt.transpose();
        let d = (v * u.transpose()).determinant().signum();
        let r = v * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * u.transpose();
        let t = qc - r * pc;
        let residuals = (0..n)
            .map(|i| MarkerResidual {
                label: labels.get(i).cloned().unwrap_or_else(|| format!("#{i}")),
                residual_mm: (r * p[i] + t - q[i]).norm(),
            })
            .collect();
        Ok(Registration {
            rotation: std::array::from_fn(|i| std::array::from_fn(|j| r[(i, j)])),
            translation_mm: [t[0], t[1], t[2]],
            residuals,
            frames: 1,
        })
    }

    /// Registers from collected frames: averages each base marker over the frames it was
    /// seen in (it must be seen in at least half of them), fits, and refuses a residual above
    /// `max_residual_mm`.
    pub fn from_frames(
        params: &Parameters,
        frames: &[Frame],
        labels: &MarkerLabels,
        base_points: &[[f64; 2]; 3],
        max_residual_mm: f64,
    ) -> Result<Registration, RegistrationError> {
        let mut mean = [[0.0; 3]; 3];
        for (k, label) in labels.base.iter().enumerate() {
            let idx = params.label_index(label).ok_or_else(|| {
                RegistrationError::UnknownLabel(label.clone(), params.labels.join(", "))
            })?;
            let seen: Vec<[f64; 3]> = frames
                .iter()
                .filter_map(|f| f.markers.get(idx).copied().flatten())
                .map(|m| m.position_mm)
                .collect();
            if seen.is_empty() || 2 * seen.len() < frames.len() {
                return Err(RegistrationError::Missing {
                    label: label.clone(),
                    seen: seen.len(),
                    frames: frames.len(),
                });
            }
            for s in &seen {
                for c in 0..3 {
                    mean[k][c] += s[c] / seen.len() as f64;
                }
            }
        }
        let mut reg = Self::fit(&labels.base, &mean, base_points)?;
        reg.frames = frames.len();
        reg.check(max_residual_mm)?;
        Ok(reg)
    }

    /// Refuses residuals above `max_mm`.
    pub fn check(&self, max_mm: f64) -> Result<(), RegistrationError> {
        let worst = self
            .residuals
            .iter()
            .max_by(|a, b| a.residual_mm.total_cmp(&b.residual_mm));
        match worst {
            Some(w) if w.residual_mm.is_nan() || w.residual_mm > max_mm => {
                Err(RegistrationError::Residual {
                    label: w.label.clone(),
                    residual_mm: w.residual_mm,
                    max_mm,
                    all: self.residuals_text(),
                })
            }
            _ => Ok(()),
        }
    }

    /// `B1 0.012 mm, B2 ...`.
    pub fn residuals_text(&self) -> String {
        self.residuals
            .iter()
            .map(|r| format!("{} {:.3} mm", r.label, r.residual_mm))
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// A capture-frame point in the robot frame (x, y, z mm; z is the distance from the
    /// robot's plane).
    pub fn point(&self, p: [f64; 3]) -> [f64; 3] {
        let r = &self.rotation;
        let t = &self.translation_mm;
        std::array::from_fn(|i| r[i][0] * p[0] + r[i][1] * p[1] + r[i][2] * p[2] + t[i])
    }

    /// A 6DOF body as a planar pose in the robot frame: x mm, y mm, phi rad (the rotation
    /// about the robot's z axis). The body's Euler angles follow QTM's default definition
    /// (rotated axes: x, then y, then z): `R_body = Rx(a1) Ry(a2) Rz(a3)`.
    pub fn pose(&self, b: &Body) -> [f64; 3] {
        let p = self.point(b.position_mm);
        let [a1, a2, a3] = b.euler_deg.map(f64::to_radians);
        let rx = Matrix3::new(
            1.0,
            0.0,
            0.0,
            0.0,
            a1.cos(),
            -a1.sin(),
            0.0,
            a1.sin(),
            a1.cos(),
        );
        let ry = Matrix3::new(
            a2.cos(),
            0.0,
            a2.sin(),
            0.0,
            1.0,
            0.0,
            -a2.sin(),
            0.0,
            a2.cos(),
        );
        let rz = Matrix3::new(
            a3.cos(),
            -a3.sin(),
            0.0,
            a3.sin(),
            a3.cos(),
            0.0,
            0.0,
            0.0,
            1.0,
        );
        let m = self.r() * rx * ry * rz;
        [p[0], p[1], m[(1, 0)].atan2(m[(0, 0)])]
    }

    /// The equivalent planar capture frame (as the plant configures it: a robot point p is
    /// seen at `R(dphi) p + d`): (dx mm, dy mm, dphi rad).
    pub fn planar_capture_frame(&self) -> (f64, f64, f64) {
        let r = &self.rotation;
        let dphi = -r[1][0].atan2(r[0][0]);
        let t = &self.translation_mm;
        // p_c = R^T (p_r - t): d = -R^T t
        let dx = -(r[0][0] * t[0] + r[1][0] * t[1] + r[2][0] * t[2]);
        let dy = -(r[0][1] * t[0] + r[1][1] * t[1] + r[2][1] * t[2]);
        (dx, dy, dphi)
    }

    /// Reads a registration file (TOML, as [`Registration::save`] writes it).
    pub fn load(path: impl AsRef<Path>) -> Result<Registration, RegistrationError> {
        let p = path.as_ref();
        let err = |message: String| RegistrationError::File {
            path: p.display().to_string(),
            message,
        };
        let text = std::fs::read_to_string(p).map_err(|e| err(e.to_string()))?;
        #[derive(Deserialize)]
        struct FileForm {
            registration: Registration,
        }
        let f: FileForm = toml::from_str(&text).map_err(|e| err(e.to_string()))?;
        let r = Matrix3::from_fn(|i, j| f.registration.rotation[i][j]);
        if !((r * r.transpose() - Matrix3::identity()).norm() < 1e-6 && r.determinant() > 0.0)
            || f.registration.translation_mm.iter().any(|v| !v.is_finite())
        {
            return Err(err("`rotation` is not a proper rotation matrix".into()));
        }
        Ok(f.registration)
    }

    /// Writes the registration as TOML with a readable header.
    pub fn save(&self, path: impl AsRef<Path>, comment: &str) -> Result<(), RegistrationError> {
        let p = path.as_ref();
        let err = |message: String| RegistrationError::File {
            path: p.display().to_string(),
            message,
        };
        #[derive(Serialize)]
        struct FileForm<'a> {
            registration: &'a Registration,
        }
        let body =
            toml::to_string(&FileForm { registration: self }).map_err(|e| err(e.to_string()))?;
        let (dx, dy, dphi) = self.planar_capture_frame();
        let text = format!(
            "# Capture frame -> robot base frame: p_robot = rotation * p_capture + translation_mm\n\
             # {comment}\n\
             # residuals: {}\n\
             # as a planar capture frame (plant.toml [capture] convention): frame_dx_mm = {dx:.4}, \
             frame_dy_mm = {dy:.4}, frame_dphi_deg = {:.5}\n{body}",
            self.residuals_text(),
            dphi.to_degrees()
        );
        std::fs::write(p, text).map_err(|e| err(e.to_string()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn base() -> [[f64; 2]; 3] {
        std::array::from_fn(|i| {
            let b = (210.0 + 120.0 * i as f64).to_radians();
            [285.0 * b.cos(), 285.0 * b.sin()]
        })
    }

    #[test]
    fn a_known_planar_frame_is_recovered_and_round_trips_through_a_file() {
        let (dx, dy, dphi) = (12.5, -7.3, 1.7f64.to_radians());
        let cap: Vec<[f64; 3]> = base()
            .iter()
            .map(|p| {
                let (s, c) = dphi.sin_cos();
                [c * p[0] - s * p[1] + dx, s * p[0] + c * p[1] + dy, 40.0]
            })
            .collect();
        let labels = MarkerLabels::default().base.to_vec();
        let r = Registration::fit(&labels, &cap, &base()).unwrap();
        let (ex, ey, ephi) = r.planar_capture_frame();
        assert!(
            (ex - dx).abs() < 1e-9 && (ey - dy).abs() < 1e-9,
            "{ex} {ey}"
        );
        assert!((ephi - dphi).abs() < 1e-12);
        assert!(r.residuals.iter().all(|m| m.residual_mm < 1e-9));
        let q = r.point(cap[1]);
        assert!((q[0] - base()[1][0]).abs() < 1e-9 && q[2].abs() < 1e-9);
        let body = Body {
            position_mm: cap[0],
            euler_deg: [0.0, 0.0, 1.7 + 5.0],
            residual_mm: None,
        };
        assert!((r.pose(&body)[2] - 5f64.to_radians()).abs() < 1e-12);
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("reg.toml");
        r.save(&f, "test").unwrap();
        assert_eq!(Registration::load(&f).unwrap(), r);
    }

    #[test]
    fn a_bad_marker_is_refused_naming_it() {
        let mut cap: Vec<[f64; 3]> = base().iter().map(|p| [p[0], p[1], 0.0]).collect();
        cap[2][0] += 5.0;
        let labels = MarkerLabels::default().base.to_vec();
        let r = Registration::fit(&labels, &cap, &base()).unwrap();
        let e = r.check(1.0).unwrap_err().to_string();
        assert!(e.contains("refused") && e.contains("B3"), "{e}");
        let line: Vec<[f64; 3]> = (0..3).map(|i| [i as f64, 0.0, 0.0]).collect();
        assert!(matches!(
            Registration::fit(&labels, &line, &base()),
            Err(RegistrationError::Degenerate)
        ));
    }
}
