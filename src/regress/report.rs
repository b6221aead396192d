//! What a regression run found, case by case, and the table the CLI prints.

use std::fmt::Write as _;
use std::path::PathBuf;

use super::compare::{DepthScore, ImageScore, Tolerance};

/// The outcome of one check (image or depth) of one case.
#[derive(Clone, Debug, PartialEq)]
pub enum Check<S> {
    /// Compared with the golden: the scores, and whether they are within tolerance.
    Compared {
        /// The comparison's scores ([`ImageScore`] or [`DepthScore`]).
        score: S,
        /// Whether `score` is within the run's [`Tolerance`].
        pass: bool,
    },
    /// No comparison was possible — the golden is missing, unreadable or of another size — which
    /// is a failure: the message says what to do.
    Unusable(String),
    /// The render was written as the new golden.
    Blessed,
}

impl<S> Check<S> {
    /// True when compared within tolerance or blessed; false when out of tolerance or unusable.
    pub fn passed(&self) -> bool {
        match self {
            Check::Compared { pass, .. } => *pass,
            Check::Unusable(_) => false,
            Check::Blessed => true,
        }
    }
}

/// One case's outcome.
#[derive(Clone, Debug, PartialEq)]
pub struct CaseResult {
    /// The case's name, the stem of its golden files (see [`super::Case::name`]).
    pub name: String,
    /// The shaded image against the golden PNG, by ꟻLIP.
    pub image: Check<ImageScore>,
    /// The primary hit distances against the golden depth EXR.
    pub depth: Check<DepthScore>,
    /// Files written for this case: on a failure the render and the error pictures (in the output
    /// folder), when blessing the new goldens.
    pub written: Vec<PathBuf>,
}

impl CaseResult {
    /// True when both the image and the depth check passed (or were blessed).
    pub fn passed(&self) -> bool {
        self.image.passed() && self.depth.passed()
    }
}

/// All cases' outcomes, in the order they ran, and the limits they were judged by.
#[derive(Clone, Debug, PartialEq)]
pub struct Report {
    /// One result per case of the config, in the order run.
    pub cases: Vec<CaseResult>,
    /// The limits the cases were judged by (the config's).
    pub tolerance: Tolerance,
}

impl Report {
    /// True when every case passed (or was blessed).
    pub fn passed(&self) -> bool {
        self.cases.iter().all(CaseResult::passed)
    }

    /// The cases that did not pass, in the order run.
    pub fn failures(&self) -> impl Iterator<Item = &CaseResult> {
        self.cases.iter().filter(|c| !c.passed())
    }

    /// A plain-text table, one row per case: ꟻLIP mean, share of outlier pixels, share of pixels
    /// whose depth is off (and the largest relative depth error), and the verdict; then, for each
    /// failure, why and which files show it. Limits are in the header, so a log of the table says
    /// what it was judged by.
    pub fn table(&self) -> String {
        let t = &self.tolerance;
        let width = self
            .cases
            .iter()
            .map(|c| c.name.len())
            .max()
            .unwrap_or(0)
            .max(4);
        let mut out = String::new();
        let _ = writeln!(
            out,
            "{:width$}  {:>9}  {:>9}  {:>9}  {:>9}  result",
            "case",
            "FLIP mean",
            format!("FLIP>{}", t.outlier_flip),
            "depth off",
            "max Δz/z",
        );
        let _ = writeln!(
            out,
            "{:width$}  {:>9}  {:>9}  {:>9}  {:>9}",
            "(limit)",
            format!("≤{}", t.flip_mean),
            format!("≤{}%", 100.0 * t.outlier_fraction),
            format!("≤{}%", 100.0 * t.depth_outlier_fraction),
            "(shown)",
        );
        for case in &self.cases {
            let (flip, outliers) = match &case.image {
                Check::Compared { score, .. } => (
                    format!("{:.5}", score.flip_mean),
                    format!("{:.3}%", 100.0 * score.outlier_fraction),
                ),
                _ => ("-".into(), "-".into()),
            };
            let (off, max) = match &case.depth {
                Check::Compared { score, .. } => (
                    format!("{:.3}%", 100.0 * score.off_fraction),
                    format!("{:.1e}", score.max_relative),
                ),
                _ => ("-".into(), "-".into()),
            };
            let verdict = if matches!(case.image, Check::Blessed) {
                "blessed"
            } else if case.passed() {
                "pass"
            } else {
                "FAIL"
            };
            let _ = writeln!(
                out,
                "{:width$}  {flip:>9}  {outliers:>9}  {off:>9}  {max:>9}  {verdict}",
                case.name
            );
        }
        let _ = writeln!(
            out,
            "depth off: pixels whose depth differs by more than {:e} of itself, or that hit in one \
             image and miss in the other; max Δz/z: the largest relative depth difference",
            t.depth_relative
        );
        for case in self.failures() {
            let _ = writeln!(out, "{}:", case.name);
            let problems = [
                ("image", image_problem(&case.image, t)),
                ("depth", depth_problem(&case.depth, t)),
            ];
            for (what, problem) in problems {
                if let Some(message) = problem {
                    let _ = writeln!(out, "  {what}: {message}");
                }
            }
            for path in &case.written {
                let _ = writeln!(out, "  wrote {}", path.display());
            }
        }
        out
    }
}

/// Why an image check failed, in words; `None` when it passed.
fn image_problem(check: &Check<ImageScore>, t: &Tolerance) -> Option<String> {
    match check {
        Check::Compared { score, pass: false } => Some(format!(
            "FLIP mean {:.5} (limit {}), {:.3}% of pixels over FLIP {} (limit {}%)",
            score.flip_mean,
            t.flip_mean,
            100.0 * score.outlier_fraction,
            t.outlier_flip,
            100.0 * t.outlier_fraction
        )),
        Check::Unusable(message) => Some(message.clone()),
        _ => None,
    }
}

/// Why a depth check failed, in words; `None` when it passed.
fn depth_problem(check: &Check<DepthScore>, t: &Tolerance) -> Option<String> {
    match check {
        Check::Compared { score, pass: false } => Some(format!(
            "{:.3}% of pixels off by more than {:e} relative or hit/miss (limit {}%); {} hit/miss mismatches, largest relative error {:.2e}",
            100.0 * score.off_fraction,
            t.depth_relative,
            100.0 * t.depth_outlier_fraction,
            score.hit_mismatches,
            score.max_relative
        )),
        Check::Unusable(message) => Some(message.clone()),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_has_a_row_per_case_and_explains_failures() {
        let pass = CaseResult {
            name: "sphere_exact".into(),
            image: Check::Compared {
                score: ImageScore {
                    flip_mean: 0.0,
                    outlier_fraction: 0.0,
                },
                pass: true,
            },
            depth: Check::Compared {
                score: DepthScore {
                    off_fraction: 0.0,
                    hit_mismatches: 0,
                    max_relative: 0.0,
                },
                pass: true,
            },
            written: vec![],
        };
        let missing = CaseResult {
            name: "blob_rbvh_q2".into(),
            image: Check::Unusable("no golden g/blob_rbvh_q2.png; run with --bless".into()),
            depth: Check::Unusable("no golden g/blob_rbvh_q2_depth.exr".into()),
            written: vec![PathBuf::from("out/blob_rbvh_q2.png")],
        };
        let report = Report {
            cases: vec![pass, missing],
            tolerance: Tolerance::default(),
        };
        assert!(!report.passed());
        let table = report.table();
        assert!(
            table.contains("sphere_exact") && table.contains("pass"),
            "{table}"
        );
        assert!(
            table.contains("FAIL") && table.contains("--bless"),
            "{table}"
        );
        assert!(table.contains("wrote out/blob_rbvh_q2.png"), "{table}");
    }
}
