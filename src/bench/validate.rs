//! Is a method wrong rather than fast? Before its speed is worth reporting, a method's hits must
//! stay close to the exact BVH's — the check tinybvh's speed test runs on every layout it times
//! (Bikker, tinybvh, `ValidateTraceResult` in `tiny_bvh_speedtest.cpp`), which exits rather than
//! report the speed of a wrong answer. An approximation is expected to differ a
//! little; these limits catch what no quality setting excuses: a broken traversal, a wrong
//! transform, hits at the wrong distance.

use super::metrics::HitErrors;

/// Most rays that may be hit by one side and missed by the other: 5%. Coarse RBVH levels miss a
/// few silhouette and thin-feature rays; a broken traversal misses or invents many more.
pub const MAX_MISS_MISMATCH: f64 = 0.05;

/// Largest tolerated 99th-percentile hit-distance error: 1% of the scene's bounding-box
/// diagonal, a few texels even at the coarsest preset (256 texels per diagonal).
pub const MAX_T_ERR_P99: f64 = 0.01;

/// Most rays on which an exact structure (the GPU's exact BVH against the CPU's, a two-level
/// exact BVH against the flat one) may hit where the other misses: 0.1%, the rays that pass
/// within rounding of an edge (`tests/agreement.rs` allows as many), not the 5% an approximation
/// may. The referee is held to what the tracers agree on, so that a wrong referee does not
/// mis-measure every approximation.
pub const REFEREE_MAX_MISS_MISMATCH: f64 = 1e-3;

/// Largest tolerated 99th-percentile hit-distance difference between two exact structures:
/// 1e-5 of the scene's diagonal, rounding (`tests/agreement.rs` allows 1e-5 relative).
pub const REFEREE_MAX_T_ERR_P99: f64 = 1e-5;

/// Why a method's `errors` (against its referee) make it invalid, or None when it passes.
pub fn invalid_reason(errors: &HitErrors) -> Option<String> {
    limits_broken(errors, MAX_MISS_MISMATCH, MAX_T_ERR_P99)
}

/// As [`invalid_reason`] for an exact structure, whose hits must be those of another exact
/// tracer to rounding: [`REFEREE_MAX_MISS_MISMATCH`], [`REFEREE_MAX_T_ERR_P99`].
pub fn invalid_reason_exact(errors: &HitErrors) -> Option<String> {
    limits_broken(errors, REFEREE_MAX_MISS_MISMATCH, REFEREE_MAX_T_ERR_P99)
}

fn limits_broken(errors: &HitErrors, max_mismatch: f64, max_t_p99: f64) -> Option<String> {
    let mut reasons = Vec::new();
    if errors.non_finite > 0 {
        reasons.push(format!(
            "{} hit(s) with a non-finite distance or normal",
            errors.non_finite
        ));
    }
    if errors.miss_mismatch_rate > max_mismatch {
        reasons.push(format!(
            "hit/miss disagrees on {:.2}% of rays (limit {}%)",
            100.0 * errors.miss_mismatch_rate,
            100.0 * max_mismatch
        ));
    }
    if let Some(t) = errors.t_err.filter(|t| t.p99 > max_t_p99) {
        reasons.push(format!(
            "hit distance error p99 is {:.3}% of the scene diagonal (limit {}%)",
            100.0 * t.p99,
            100.0 * max_t_p99
        ));
    }
    (!reasons.is_empty()).then(|| reasons.join("; "))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bench::metrics::Summary;

    fn errors(mismatch: f64, p99: f64) -> HitErrors {
        HitErrors {
            rays: 100,
            miss_mismatch_rate: mismatch,
            t_err: Some(Summary {
                mean: p99 / 2.0,
                p99,
                max: p99,
            }),
            t_err_object: None,
            normal_err_deg: None,
            back_facing_rate: 0.0,
            non_finite: 0,
        }
    }

    #[test]
    fn limits_are_exclusive_and_each_reason_is_named() {
        assert_eq!(invalid_reason(&errors(0.05, 0.01)), None);
        let miss = invalid_reason(&errors(0.06, 0.0)).unwrap();
        assert!(miss.contains("6.00%"), "{miss}");
        let far = invalid_reason(&errors(0.0, 0.02)).unwrap();
        assert!(far.contains("distance"), "{far}");
        let both = invalid_reason(&HitErrors {
            non_finite: 1,
            ..errors(0.5, 0.5)
        })
        .unwrap();
        assert_eq!(both.matches("; ").count(), 2, "{both}");
    }

    /// An exact structure is held to rounding: what passes as an approximation is a broken
    /// referee.
    #[test]
    fn an_exact_structure_is_held_to_rounding() {
        assert_eq!(invalid_reason_exact(&errors(0.001, 1e-5)), None);
        assert!(invalid_reason(&errors(0.04, 0.009)).is_none());
        let wrong = invalid_reason_exact(&errors(0.04, 0.009)).unwrap();
        assert!(
            wrong.contains("4.00%") && wrong.contains("distance"),
            "{wrong}"
        );
        assert!(invalid_reason_exact(&errors(0.0, 2e-5)).is_some());
    }
}
