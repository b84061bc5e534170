//! Summary statistics of errors and the ISO 9283 pose-repeatability figures.

use serde::Serialize;

/// Mean, maximum, standard deviation and RMS of a set of non-negative errors.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct Summary {
    /// Number of values.
    pub n: usize,
    /// Mean.
    pub mean: f64,
    /// Largest value.
    pub max: f64,
    /// Sample standard deviation (n - 1 in the denominator; 0 for one value).
    pub sigma: f64,
    /// Root mean square.
    pub rms: f64,
}

impl Summary {
    /// The summary of `values` (`None` when empty).
    pub fn of(values: &[f64]) -> Option<Summary> {
        if values.is_empty() {
            return None;
        }
        let n = values.len() as f64;
        let mean = values.iter().sum::<f64>() / n;
        let ss = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>();
        Some(Summary {
            n: values.len(),
            mean,
            max: values.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            sigma: if values.len() > 1 {
                (ss / (n - 1.0)).sqrt()
            } else {
                0.0
            },
            rms: (values.iter().map(|v| v * v).sum::<f64>() / n).sqrt(),
        })
    }

    /// The same figures as a percentage of `length` (e.g. of l_C).
    pub fn percent_of(&self, length: f64) -> Summary {
        let f = 100.0 / length;
        Summary {
            n: self.n,
            mean: self.mean * f,
            max: self.max * f,
            sigma: self.sigma * f,
            rms: self.rms * f,
        }
    }
}

/// ISO 9283 positional repeatability of one target visited n times: the barycentre of the
/// attained positions, the distances l_j to it, RP = mean(l) + 3 S_l.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct IsoRepeatability {
    /// Visits.
    pub n: usize,
    /// Barycentre (x, y), mm.
    pub barycentre: [f64; 2],
    /// Mean distance to the barycentre, mm.
    pub l_mean: f64,
    /// Sample standard deviation of the distances, mm.
    pub s_l: f64,
    /// RP = l_mean + 3 S_l, mm.
    pub rp: f64,
    /// Orientation: mean attained phi (deg) and the ISO figure for orientation,
    /// RP_phi = +-3 S_phi (the sample deviation of phi about its mean), deg.
    pub phi_mean: f64,
    /// 3 S_phi, deg.
    pub rp_phi: f64,
}

/// ISO 9283 repeatability of one target from its attained poses (x mm, y mm, phi deg);
/// `None` with fewer than two visits.
pub fn iso_repeatability(poses: &[[f64; 3]]) -> Option<IsoRepeatability> {
    if poses.len() < 2 {
        return None;
    }
    let n = poses.len() as f64;
    let bx = poses.iter().map(|p| p[0]).sum::<f64>() / n;
    let by = poses.iter().map(|p| p[1]).sum::<f64>() / n;
    let l: Vec<f64> = poses.iter().map(|p| (p[0] - bx).hypot(p[1] - by)).collect();
    let l_mean = l.iter().sum::<f64>() / n;
    let s_l = (l.iter().map(|v| (v - l_mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    let phis: Vec<f64> = poses.iter().map(|p| p[2]).collect();
    let phi_mean = circular_mean_deg(&phis);
    let s_phi = (phis
        .iter()
        .map(|p| crate::step2::angle_diff_deg(*p, phi_mean).powi(2))
        .sum::<f64>()
        / (n - 1.0))
        .sqrt();
    Some(IsoRepeatability {
        n: poses.len(),
        barycentre: [bx, by],
        l_mean,
        s_l,
        rp: l_mean + 3.0 * s_l,
        phi_mean,
        rp_phi: 3.0 * s_phi,
    })
}

/// Circular mean of angles in degrees.
pub fn circular_mean_deg(a: &[f64]) -> f64 {
    let (s, c) = a.iter().fold((0.0, 0.0), |acc, v| {
        let (s, c) = v.to_radians().sin_cos();
        (acc.0 + s, acc.1 + c)
    });
    s.atan2(c).to_degrees()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn summary_by_hand() {
        // 1, 2, 3, 4: mean 2.5, max 4, sigma sqrt(5/3), rms sqrt(7.5)
        let s = Summary::of(&[1.0, 2.0, 3.0, 4.0]).unwrap();
        assert_eq!(s.n, 4);
        assert!((s.mean - 2.5).abs() < 1e-15);
        assert_eq!(s.max, 4.0);
        assert!((s.sigma - (5.0f64 / 3.0).sqrt()).abs() < 1e-15);
        assert!((s.rms - 7.5f64.sqrt()).abs() < 1e-15);
        let p = s.percent_of(125.0);
        assert!((p.mean - 2.0).abs() < 1e-12);
        assert!(Summary::of(&[]).is_none());
        assert_eq!(Summary::of(&[3.0]).unwrap().sigma, 0.0);
    }

    #[test]
    fn iso_repeatability_by_hand() {
        // Four visits at (+-1, 0), (0, +-1): barycentre (0, 0), every l = 1, S_l = 0, RP = 1.
        let p = [
            [1.0, 0.0, 1.0],
            [-1.0, 0.0, -1.0],
            [0.0, 1.0, 1.0],
            [0.0, -1.0, -1.0],
        ];
        let r = iso_repeatability(&p).unwrap();
        assert!(r.barycentre[0].abs() < 1e-15 && r.barycentre[1].abs() < 1e-15);
        assert!((r.rp - 1.0).abs() < 1e-15 && r.s_l.abs() < 1e-15);
        // phi: +-1 about 0: S_phi = sqrt(4 / 3), RP_phi = 3 S_phi
        assert!(r.phi_mean.abs() < 1e-12);
        assert!((r.rp_phi - 3.0 * (4.0f64 / 3.0).sqrt()).abs() < 1e-12);
        // Three visits at x = 0, 1, 5 on a line: barycentre 2, l = 2, 1, 3, mean 2, S_l = 1,
        // RP = 5.
        let q = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [5.0, 0.0, 0.0]];
        let r = iso_repeatability(&q).unwrap();
        assert!((r.barycentre[0] - 2.0).abs() < 1e-15);
        assert!((r.l_mean - 2.0).abs() < 1e-15 && (r.s_l - 1.0).abs() < 1e-15);
        assert!((r.rp - 5.0).abs() < 1e-15);
        assert!(iso_repeatability(&q[..1]).is_none());
    }

    #[test]
    fn circular_mean_wraps() {
        assert!((circular_mean_deg(&[179.0, -179.0]).abs() - 180.0).abs() < 1e-9);
        assert!((circular_mean_deg(&[10.0, 20.0]) - 15.0).abs() < 1e-12);
    }
}
