//! Whether an extended model is a physical explanation: its geometry near the drawing the
//! analysis started from, springs and creep of the right sign, a small capture frame error, no
//! motion that leads its command.

use crate::attribution::Options;
use pcr_robot::RobotConfig;

/// Why a model is not a physical explanation, if it is not: its geometry more than
/// `max_geometry_change` (mm, deg) away from the drawing the analysis started from (the
/// calibration parameters would then only mimic another cause), or springs, creep or a latency
/// of the wrong sign.
pub(crate) fn unphysical(
    c: &RobotConfig,
    current: &RobotConfig,
    drawing: &RobotConfig,
    opts: &Options,
) -> Option<String> {
    let lim = opts.max_geometry_change;
    let params = |l: &pcr_robot::LegConfig| {
        [
            ("psi_deg", l.psi_deg),
            ("l_c_mm", l.l_c_mm),
            ("r_p_mm", l.r_p_mm),
            ("theta_p_deg", l.theta_p_deg),
            ("l_st_mm", l.l_st_mm),
            ("r_base_mm", l.r_base_mm),
            ("beta_deg", l.beta_deg),
        ]
    };
    // How far beyond the bound a geometry is, summed over the parameters: a candidate may not
    // push it further out (it may bring a geometry the calibration pushed out back).
    let excess = |c: &RobotConfig| -> (f64, Vec<String>) {
        let mut total = 0.0;
        let mut far = Vec::new();
        for i in 0..3 {
            let (n, d) = (params(&c.legs[i]), params(&drawing.legs[i]));
            for k in 0..n.len() {
                let away = (n[k].1 - d[k].1).abs();
                if away > lim {
                    total += (away - lim).powi(2);
                    far.push(format!("{}[{}] {:+.2}", n[k].0, i + 1, n[k].1 - d[k].1));
                }
            }
        }
        (total, far)
    };
    let (new_excess, far) = excess(c);
    let (old_excess, _) = excess(current);
    let mut why = Vec::new();
    if new_excess > old_excess + 1e-9 {
        why.push(format!(
            "the geometry would leave the drawing ({}; more than {lim} mm or deg)",
            far.join(", ")
        ));
    }
    let e = &c.effects;
    if let Some(f) = &e.frame {
        // A registration off by more than this would be seen at once: 1 deg is 5 mm at the
        // base points.
        if f.dx_mm.hypot(f.dy_mm) > lim || f.dphi_deg.abs() > lim / 3.0 {
            why.push(format!(
                "a capture frame off by ({:.2}, {:.2}) mm and {:.2} deg",
                f.dx_mm, f.dy_mm, f.dphi_deg
            ));
        }
    }
    if let Some(k) = &e.compliance {
        if k.k_m_n_mm_per_rad < 0.0 || k.k_p_n_mm_per_rad < 0.0 {
            why.push(format!(
                "negative joint springs (k_M {:.1}, k_P {:.1} N mm/rad)",
                k.k_m_n_mm_per_rad, k.k_p_n_mm_per_rad
            ));
        }
    }
    if let Some(cr) = &e.creep {
        if cr.gain.iter().any(|g| *g < 0.0) {
            why.push(format!(
                "a tendon that shortens under load (creep gains {:?})",
                cr.gain
            ));
        }
    }
    if let Some(l) = &e.latency {
        if l.latency_s < -0.01 {
            why.push(format!(
                "the motion leads the command by {:.3} s",
                -l.latency_s
            ));
        }
    }
    (!why.is_empty()).then(|| format!("unphysical: {}", why.join(", ")))
}
