//! The statistics of `--stats` (`RenderSettings::stats`): per-strategy counters and the
//! ellipsoid queries' work, summed over the waves by the tracer, read here.

use super::{BidirectionalTracer, StrategyStats};
use crate::integrator::Method;

impl BidirectionalTracer<'_> {
    /// Mean work of one ellipsoid query so far: loop iterations over BVH nodes and triangles,
    /// and triangles tested (None without `stats` or before any query).
    pub fn query_cost(&self) -> Option<(f64, f64)> {
        let queries: u64 = self.stats.as_ref()?.iter().map(|s| s.evaluated).sum();
        (queries > 0).then(|| (self.query_work[0] as f64 / queries as f64, self.query_work[1] as f64 / queries as f64))
    }

    /// Strategy counters so far (None unless the settings asked for statistics).
    pub fn strategy_stats(&self) -> Option<&[StrategyStats]> {
        self.stats.as_deref()
    }

    /// Connections the ellipsoid guards left out so far (with `stats` on): spheroids thinner
    /// than the needle guard, and sampled points off the target length.
    pub fn guarded(&self) -> (u64, u64) {
        (self.query_work[3], self.query_work[4])
    }

    /// A combined render's direct half, with `stats` on: its weights taken from per-slot sums
    /// that were checked against the walk of the whole path, and those that differed.
    pub fn family_weights_checked(&self) -> (u64, u64) {
        (self.query_work[5], self.query_work[6])
    }

    /// The statistics of `--stats` as text (None without them): per strategy, and the ellipsoid
    /// queries' work or the check of a combined render's direct-family weights.
    pub(super) fn stats_text(&self) -> Option<String> {
        let stats = self.stats.as_ref()?;
        let ellipsoidal = self.method == Method::Ellipsoidal;
        let mut out = if ellipsoidal {
            String::from(
                "(s,t) of the full path: s light-subpath vertices, the ellipsoidal vertex and t - 1 camera-subpath \
                 vertices; (1,1): spherical connections to lights seen directly; with directional lights, (1,t) also \
                 counts camera vertex t - 1 joined to the light along its beam (`no intersection`: the gate weighs \
                 its length zero)\n\
                 strategy (s,t)      queries  no intersection  shadow rays\n",
            )
        } else {
            String::from("strategy (s,t)  connections  skipped by gate  shadow rays\n")
        };
        let mut total = StrategyStats::default();
        for st in stats {
            out += &format!(
                "({:>2},{:>2})        {:>12}  {:>15}  {:>11}\n",
                st.s, st.t, st.evaluated, st.skipped_by_gate, st.shadow_rays
            );
            total.evaluated += st.evaluated;
            total.skipped_by_gate += st.skipped_by_gate;
            total.shadow_rays += st.shadow_rays;
        }
        out += &format!(
            "total          {:>12}  {:>15}  {:>11}\n",
            total.evaluated, total.skipped_by_gate, total.shadow_rays
        );
        if ellipsoidal {
            let q = total.evaluated.max(1) as f64;
            let [nodes, tested, intersected, needles, off_length, ..] = self.query_work;
            out += &format!(
                "per ellipsoid query: {:.1} loop iterations (BVH nodes and triangles), {:.2} triangles tested, {:.2} \
                 triangles intersected\n\
                 guards: {needles} spheroids thinner than the needle guard skipped, {off_length} sampled points off \
                 the target length dropped\n",
                nodes as f64 / q,
                tested as f64 / q,
                intersected as f64 / q
            );
        }
        let (checked, differing) = self.family_weights_checked();
        if checked > 0 {
            out += &format!(
                "direct-family weights from per-slot sums: {checked} checked against the walk of their path, \
                 {differing} differ\n"
            );
        }
        Some(out)
    }
}
