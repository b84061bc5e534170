//! Whether an extended model is a physical explanation: its geometry near the drawing the
//! analysis started from, and every effect it declares plausible
//! ([`crate::effects::Effect::unphysical`]: springs and creep of the right sign, a small capture
//! frame error, no motion that leads its command).

use crate::effects;
use crate::options::Options;
use pcr_robot::RobotConfig;

/// Why a model is not a physical explanation, if it is not: its geometry more than
/// `max_geometry_change` (mm, deg) away from the drawing the analysis started from (the
/// calibration parameters would then only mimic another cause), or an effect's entry that is
/// not physical. The effects' reasons are listed from the last entry of the robot file back to
/// the first ([`crate::effects::Effect::file_position`]).
pub(crate) fn unphysical(
    c: &RobotConfig,
    current: &RobotConfig,
    drawing: &RobotConfig,
    opts: &Options,
) -> Option<String> {
    let mut why: Vec<String> = leaves_drawing(c, current, drawing, opts)
        .into_iter()
        .collect();
    why.extend(effects_unphysical(c, opts.max_geometry_change));
    (!why.is_empty()).then(|| format!("unphysical: {}", why.join(", ")))
}

/// Why the effects `c` declares are not physical (springs or creep of the wrong sign, a
/// capture frame beyond a registration error, a motion that leads its command), from the last
/// entry of the robot file back to the first; empty when they are. `max_change`: the
/// geometry's tolerance, mm or deg (`Options::max_geometry_change`), which scales the frame's.
pub(crate) fn effects_unphysical(c: &RobotConfig, max_change: f64) -> Vec<String> {
    effects::in_file_order()
        .iter()
        .rev()
        .filter_map(|e| e.unphysical(&c.effects, max_change))
        .collect()
}

/// Why the geometry of `c` is further from the drawing than that of `current` (beyond
/// `max_geometry_change` mm or deg), if it is.
pub(crate) fn leaves_drawing(
    c: &RobotConfig,
    current: &RobotConfig,
    drawing: &RobotConfig,
    opts: &Options,
) -> Option<String> {
    let lim = opts.max_geometry_change;
    let (new_excess, far) = excess(c, drawing, lim);
    let (old_excess, _) = excess(current, drawing, lim);
    (new_excess > old_excess + 1e-9).then(|| {
        format!(
            "the geometry would leave the drawing ({}; more than {lim} mm or deg)",
            far.join(", ")
        )
    })
}

/// How far beyond `lim` (mm or deg) of the drawing the geometry of `c` is: the squares of the
/// parameters' excesses summed, with the parameters beyond it named. A candidate may not push
/// a geometry further out (it may bring one the calibration pushed out back).
pub(crate) fn excess(c: &RobotConfig, drawing: &RobotConfig, lim: f64) -> (f64, Vec<String>) {
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
}

#[cfg(test)]
mod tests {
    use super::*;
    use pcr_robot::effects::{Compliance, Creep, FrameCorrection, Latency};

    #[test]
    fn reasons_go_from_the_frame_back_to_the_latency() {
        let drawing = RobotConfig::nominal();
        let mut c = drawing.clone();
        c.effects.latency = Some(Latency { latency_s: -0.05 });
        c.effects.creep = Some(Creep {
            gain: [-0.1, 0.0, 0.0],
            time_constant_s: 10.0,
        });
        c.effects.compliance = Some(Compliance {
            ei_n_mm2: 6.5e4,
            k_m_n_mm_per_rad: -10.0,
            ..Compliance::default()
        });
        c.effects.frame = Some(FrameCorrection {
            dx_mm: 5.0,
            dy_mm: 0.0,
            dphi_deg: 0.0,
        });
        assert_eq!(
            unphysical(&c, &drawing, &drawing, &Options::default()).as_deref(),
            Some(
                "unphysical: a capture frame off by (5.00, 0.00) mm and 0.00 deg, negative joint \
                 springs (k_M -10.0, k_P 0.0 N mm/rad), a tendon that shortens under load (creep \
                 gains [-0.1, 0.0, 0.0]), the motion leads the command by 0.050 s"
            )
        );
        assert_eq!(
            unphysical(&drawing, &drawing, &drawing, &Options::default()),
            None
        );
    }

    /// The excess counts each parameter beyond the limit by the square of what is beyond, and
    /// a geometry brought nearer the drawing (still beyond) leaves the drawing no further.
    #[test]
    fn the_excess_is_what_lies_beyond_the_limit() {
        let drawing = RobotConfig::nominal();
        let mut c = drawing.clone();
        c.legs[0].l_c_mm -= 5.0;
        c.legs[2].psi_deg += 2.0;
        let (e, far) = excess(&c, &drawing, 3.0);
        assert!((e - 4.0).abs() < 1e-9, "{e}");
        assert_eq!(far, vec!["l_c_mm[1] -5.00".to_string()]);
        let mut nearer = c.clone();
        nearer.legs[0].l_c_mm += 1.0;
        assert!((excess(&nearer, &drawing, 3.0).0 - 1.0).abs() < 1e-9);
        let opts = Options {
            max_geometry_change: 3.0,
            ..Options::default()
        };
        assert!(leaves_drawing(&nearer, &c, &drawing, &opts).is_none());
        assert!(leaves_drawing(&c, &nearer, &drawing, &opts).is_some());
        assert_eq!(excess(&drawing, &drawing, 3.0).0, 0.0);
    }
}
