//! One continuum segment on its own (`pcr calibrate leg`): all 13 Table I functions, in both
//! readings (symmetric and asymmetric, `pcr_robot::MapReading`), fitted to a segment's measured
//! tip positions, in the segment's own frame.
//!
//! Input: a CSV (leading `#` comment lines allowed) with the tendon displacement `dl_mm` (or the
//! motor position `q1`, converted with a robot leg's actuation), the measured point `mx_mm`,
//! `my_mm` in the segment frame (base point at the origin, base tangent +y, positive curvature
//! bends towards +x; the point is the segment tip, or the end of the rigid extension when
//! `l_ce_mm > 0`), and optionally `set` (`train` / `test`). Other columns are ignored. Without
//! `set`, a seeded random third of the rows is held out.

use crate::calibrate::Readings;
use crate::step1::{self, FreeGeometry, LegFit, LegObservation};
use pcr_robot::{Actuation, LegConfig, MapForm, MapReading, TendonMapKind};
use rand::seq::SliceRandom;
use rand::SeedableRng;
use serde::Serialize;
use std::path::Path;

/// Why a segment data file cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SegmentError {
    /// The file cannot be read.
    #[error("{file}: {message}")]
    Io {
        /// The file.
        file: String,
        /// The OS message.
        message: String,
    },
    /// The header lacks a column.
    #[error("{file}: header (line {line}): {message}")]
    Header {
        /// The file.
        file: String,
        /// 1-based line.
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// A cell is empty or not a number.
    #[error("{file}: line {line}, column `{column}`: {message} (cell {cell:?})")]
    Cell {
        /// The file.
        file: String,
        /// 1-based line.
        line: usize,
        /// Column.
        column: String,
        /// The cell.
        cell: String,
        /// What is wrong.
        message: String,
    },
    /// Too few rows or a bad setting.
    #[error("{file}: {message}")]
    Data {
        /// The file.
        file: String,
        /// What is wrong.
        message: String,
    },
}

/// One row of a segment file.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SegmentPoint {
    /// Tendon displacement, mm.
    pub dl_mm: f64,
    /// Measured point in the segment frame, mm.
    pub m: [f64; 2],
    /// The given split (None without a `set` column).
    pub test: Option<bool>,
    /// 1-based line in the file.
    pub line: usize,
}

/// Reads a segment file. `actuation` converts a `q1` column to displacement when there is no
/// `dl_mm` column.
pub fn read_points(
    path: &Path,
    actuation: Option<&Actuation>,
) -> Result<Vec<SegmentPoint>, SegmentError> {
    let file = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| SegmentError::Io {
        file: file.clone(),
        message: e.to_string(),
    })?;
    parse_points(&text, &file, actuation)
}

/// [`read_points`] on text; `file` names it in errors.
pub fn parse_points(
    text: &str,
    file: &str,
    actuation: Option<&Actuation>,
) -> Result<Vec<SegmentPoint>, SegmentError> {
    let mut lines = text.lines().enumerate().map(|(k, l)| (k + 1, l));
    let (header_line, header) = loop {
        match lines.next() {
            None => {
                return Err(SegmentError::Header {
                    file: file.into(),
                    line: 1,
                    message: "no header row".into(),
                })
            }
            Some((_, l)) if l.trim_start().starts_with('#') || l.trim().is_empty() => continue,
            Some((k, l)) => break (k, l.trim_start_matches('\u{feff}')),
        }
    };
    let cols: Vec<&str> = header.split(',').map(str::trim).collect();
    let find = |name: &str| cols.iter().position(|c| *c == name);
    let header_err = |message: String| SegmentError::Header {
        file: file.into(),
        line: header_line,
        message,
    };
    let (x_col, x_name, per_unit) = match (find("dl_mm"), find("q1"), actuation) {
        (Some(c), _, _) => (c, "dl_mm", 1.0),
        (None, Some(c), Some(a)) => (c, "q1", a.mm_per_step()),
        (None, Some(_), None) => {
            return Err(header_err(
                "column `q1` needs `--robot` for the actuation (mm per step); or give `dl_mm`"
                    .into(),
            ))
        }
        (None, None, _) => return Err(header_err(
            "required column `dl_mm` (tendon displacement, mm) or `q1` (motor steps) is missing"
                .into(),
        )),
    };
    let mx =
        find("mx_mm").ok_or_else(|| header_err("required column `mx_mm` is missing".into()))?;
    let my =
        find("my_mm").ok_or_else(|| header_err("required column `my_mm` is missing".into()))?;
    let set = find("set");
    let mut out = Vec::new();
    for (line, l) in lines {
        if l.trim().is_empty() || l.trim_start().starts_with('#') {
            continue;
        }
        let cells: Vec<&str> = l.split(',').map(str::trim).collect();
        let cell = |c: usize, name: &str| -> Result<f64, SegmentError> {
            let v = cells.get(c).copied().unwrap_or("");
            let bad = |message: &str| SegmentError::Cell {
                file: file.into(),
                line,
                column: name.into(),
                cell: v.into(),
                message: message.into(),
            };
            if v.is_empty() {
                return Err(bad("empty cell where a number is needed"));
            }
            let x: f64 = v.parse().map_err(|_| bad("not a number"))?;
            if !x.is_finite() {
                return Err(bad("not a finite number"));
            }
            Ok(x)
        };
        let test = match set {
            None => None,
            Some(c) => match cells.get(c).copied().unwrap_or("") {
                "train" => Some(false),
                "test" => Some(true),
                v => {
                    return Err(SegmentError::Cell {
                        file: file.into(),
                        line,
                        column: "set".into(),
                        cell: v.into(),
                        message: "must be `train` or `test`".into(),
                    })
                }
            },
        };
        out.push(SegmentPoint {
            dl_mm: cell(x_col, x_name)? * per_unit,
            m: [cell(mx, "mx_mm")?, cell(my, "my_mm")?],
            test,
            line,
        });
    }
    Ok(out)
}

/// Settings of a segment fit.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct SegmentOptions {
    /// Segment length l_C, mm.
    pub l_c_mm: f64,
    /// Rigid extension to the measured point, mm.
    pub l_ce_mm: f64,
    /// Also fit the base orientation psi (a frame misaligned by a few degrees).
    pub fit_psi: bool,
    /// Also fit l_C.
    pub fit_l_c: bool,
    /// Seed of the random split.
    pub seed: u64,
    /// Fraction of rows held out by the random split.
    pub test_fraction: f64,
    /// Which readings of the forms are fitted.
    pub reading: Readings,
}

/// One function in one reading fitted to the segment.
#[derive(Debug, Clone, Serialize)]
pub struct SegmentFunction {
    /// Table I number.
    pub index: usize,
    /// The reading.
    pub reading: MapReading,
    /// The Table I number, `a` for the asymmetric reading (`4`, `4a`).
    pub label: String,
    /// Family name.
    pub name: &'static str,
    /// The paper's form.
    pub form: &'static str,
    /// The form as evaluated for every dl.
    pub extended_form: String,
    /// Coefficients k0, k1, ... (1/mm, see `params` for units and uncertainties); for dl >= 0
    /// in the asymmetric reading.
    pub coefficients: Vec<f64>,
    /// The asymmetric reading's coefficients for dl < 0 (without k0; empty when symmetric).
    pub coefficients_neg: Vec<f64>,
    /// The fit (parameters with uncertainties, RMS, status); `None` when it failed.
    pub fit: Option<LegFit>,
    /// Training RMS of the measured point, mm.
    pub train_rms_mm: Option<f64>,
    /// Test RMS, mm.
    pub test_rms_mm: Option<f64>,
    /// Why the fit failed.
    pub error: Option<String>,
}

/// The result of `pcr calibrate leg`.
#[derive(Debug, Clone, Serialize)]
pub struct SegmentResult {
    /// The data file.
    pub file: String,
    /// Settings.
    pub options: SegmentOptions,
    /// Rows.
    pub points: usize,
    /// Training rows.
    pub n_train: usize,
    /// Test rows.
    pub n_test: usize,
    /// `column` or `seeded`.
    pub split: String,
    /// Range of the tendon displacement in the data, mm.
    pub dl_range_mm: [f64; 2],
    /// Every function in Table I order, each in the readings fitted (symmetric first).
    pub functions: Vec<SegmentFunction>,
    /// The label (`4`, `4a`) of the function and reading with the lowest test RMS.
    pub best: Option<String>,
}

/// Fits all 13 functions to a segment's points.
pub fn fit_segment(
    file: &str,
    points: &[SegmentPoint],
    opts: &SegmentOptions,
) -> Result<SegmentResult, SegmentError> {
    let data_err = |message: String| SegmentError::Data {
        file: file.into(),
        message,
    };
    if !(opts.l_c_mm > 0.0 && opts.l_c_mm.is_finite()) {
        return Err(data_err(format!(
            "--l-c-mm = {}: the segment length must be a positive number of mm",
            opts.l_c_mm
        )));
    }
    if !(opts.l_ce_mm >= 0.0 && opts.l_ce_mm.is_finite()) {
        return Err(data_err(format!(
            "--l-ce-mm = {}: the extension must be >= 0 mm",
            opts.l_ce_mm
        )));
    }
    let given = points.iter().filter(|p| p.test.is_some()).count();
    let mut test_flags: Vec<bool> = points.iter().map(|p| p.test.unwrap_or(false)).collect();
    let split = if given > 0 {
        "column".to_string()
    } else {
        let mut idx: Vec<usize> = (0..points.len()).collect();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(opts.seed);
        idx.shuffle(&mut rng);
        let n_test = (points.len() as f64 * opts.test_fraction).round() as usize;
        for &k in &idx[..n_test] {
            test_flags[k] = true;
        }
        format!(
            "seeded (seed {}, {:.3} of the rows held out)",
            opts.seed, opts.test_fraction
        )
    };
    let obs = |test: bool| -> Vec<LegObservation> {
        points
            .iter()
            .zip(&test_flags)
            .filter(|(_, t)| **t == test)
            .map(|(p, _)| LegObservation {
                dl_mm: p.dl_mm,
                m: p.m,
            })
            .collect()
    };
    let (train, test) = (obs(false), obs(true));
    if train.len() < 4 {
        return Err(data_err(format!(
            "{} training rows: at least 4 are needed (7 or more to fit every Table I function)",
            train.len()
        )));
    }
    let base = LegConfig {
        r_base_mm: 0.0,
        beta_deg: 0.0,
        psi_deg: 0.0,
        l_c_mm: opts.l_c_mm,
        l_ce_mm: opts.l_ce_mm,
        ..LegConfig::nominal(0)
    };
    let free = FreeGeometry {
        psi: opts.fit_psi,
        l_c: opts.fit_l_c,
        ..FreeGeometry::NONE
    };
    let forms = TendonMapKind::ALL.iter().flat_map(|&kind| {
        opts.reading
            .fitted()
            .iter()
            .map(move |&reading| MapForm { kind, reading })
    });
    let functions: Vec<SegmentFunction> = forms
        .map(|form| {
            let kind = form.kind;
            let r = step1::fit_leg("segment", None, &base, free, form, &train, &test);
            let (fit, error) = match r {
                Ok(f) => (Some(f), None),
                Err(e) => (None, Some(e.to_string())),
            };
            SegmentFunction {
                index: kind.table_index(),
                reading: form.reading,
                label: form.label(),
                name: kind.name(),
                form: kind.paper_form(),
                extended_form: form.evaluated_form(),
                coefficients: fit
                    .as_ref()
                    .map(|f| f.config.tendon_map.coeffs.clone())
                    .unwrap_or_default(),
                coefficients_neg: fit
                    .as_ref()
                    .map(|f| f.config.tendon_map.coeffs_neg.clone())
                    .unwrap_or_default(),
                train_rms_mm: fit.as_ref().map(|f| f.train_rms_mm),
                test_rms_mm: fit.as_ref().and_then(|f| f.test_rms_mm),
                fit,
                error,
            }
        })
        .collect();
    let best = functions
        .iter()
        .filter(|f| f.fit.as_ref().is_some_and(|f| f.converged))
        .filter_map(|f| Some((&f.label, f.test_rms_mm.or(f.train_rms_mm)?)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|b| b.0.clone());
    let (lo, hi) = points
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |a, p| {
            (a.0.min(p.dl_mm), a.1.max(p.dl_mm))
        });
    Ok(SegmentResult {
        file: file.into(),
        options: *opts,
        points: points.len(),
        n_train: train.len(),
        n_test: test.len(),
        split,
        dl_range_mm: [lo, hi],
        functions,
        best,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use pcr_kinematics::Leg;
    use pcr_robot::TendonMapSpec;

    fn opts() -> SegmentOptions {
        SegmentOptions {
            l_c_mm: 100.0,
            l_ce_mm: 0.0,
            fit_psi: false,
            fit_l_c: false,
            seed: 3,
            test_fraction: 1.0 / 3.0,
            reading: Readings::PerLeg,
        }
    }

    #[test]
    fn recovers_a_polynomial_segment_and_names_the_best() {
        // A segment of 100 mm whose curvature is k0 + k1 dl + k2 dl^2 (dl > 0 only).
        let mut cfg = LegConfig {
            r_base_mm: 0.0,
            psi_deg: 0.0,
            l_c_mm: 100.0,
            l_ce_mm: 0.0,
            ..LegConfig::nominal(0)
        };
        cfg.tendon_map = TendonMapSpec::symmetric(TendonMapKind::Poly2, vec![2e-4, 1.2e-3, 4e-5]);
        let leg = Leg::from_config(&cfg);
        let mut text = String::from("# bench data\nsample,dl_mm,mx_mm,my_mm\n");
        for k in 0..45 {
            let dl = 0.2 + 0.2 * k as f64;
            let m = step1::predict_m(&leg, dl);
            text += &format!("{k},{dl},{},{}\n", m[0], m[1]);
        }
        let pts = parse_points(&text, "bench.csv", None).unwrap();
        assert_eq!(pts.len(), 45);
        let r = fit_segment("bench.csv", &pts, &opts()).unwrap();
        assert_eq!((r.n_train, r.n_test), (30, 15));
        // dl > 0 only: the asymmetric readings have no points for their dl < 0 coefficients.
        assert_eq!(r.functions.len(), 26);
        let asym = &r.functions[5];
        assert_eq!(
            (asym.label.as_str(), asym.reading),
            ("3a", MapReading::Asymmetric)
        );
        assert!(
            asym.error.as_ref().unwrap().contains("dl < 0"),
            "{:?}",
            asym.error
        );
        let f3 = &r.functions[4];
        assert_eq!(f3.index, 3);
        assert!(f3.test_rms_mm.unwrap() < 1e-6, "{:?}", f3.test_rms_mm);
        assert!((f3.coefficients[2] - 4e-5).abs() < 1e-9);
        // the best function fits to round-off as well (3 or a superset of it)
        let best = r
            .functions
            .iter()
            .find(|f| Some(&f.label) == r.best.as_ref())
            .unwrap();
        assert!(best.test_rms_mm.unwrap() < 1e-6);
        assert!(r.functions[18].test_rms_mm.unwrap() > 0.01);
    }

    #[test]
    fn bad_files_name_the_line_and_column() {
        let e = parse_points("dl_mm,mx_mm\n1,2\n", "a.csv", None).unwrap_err();
        assert!(e.to_string().contains("my_mm"), "{e}");
        let e = parse_points("dl_mm,mx_mm,my_mm\n1,2,\n", "a.csv", None).unwrap_err();
        assert!(
            e.to_string().contains("line 2") && e.to_string().contains("my_mm"),
            "{e}"
        );
        let e = parse_points("dl_mm,mx_mm,my_mm\n1,2,x\n", "a.csv", None).unwrap_err();
        assert!(e.to_string().contains("not a number"), "{e}");
        let e = parse_points("q1,mx_mm,my_mm\n1,2,3\n", "a.csv", None).unwrap_err();
        assert!(e.to_string().contains("--robot"), "{e}");
        let e = parse_points("dl_mm,mx_mm,my_mm,set\n1,2,3,val\n", "a.csv", None).unwrap_err();
        assert!(e.to_string().contains("`set`"), "{e}");
        let pts = parse_points(
            "q1,mx_mm,my_mm\n100,2,3\n",
            "a.csv",
            Some(&Actuation::default()),
        )
        .unwrap();
        assert!((pts[0].dl_mm - 100.0 * Actuation::default().mm_per_step()).abs() < 1e-12);
        let e = fit_segment("a.csv", &pts, &opts()).unwrap_err();
        assert!(e.to_string().contains("training rows"), "{e}");
    }
}
