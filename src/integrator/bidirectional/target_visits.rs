//! How a render shares out extra visits of each pixel's stratified bins (ellipsoidal
//! connections on a transient gate): the band index of an NLOS capture, whose masses share them
//! out without samples, or a pilot render, whose transient does.

use anyhow::Result;

use super::BidirectionalTracer;
use crate::gpu::resources::read_buffer;
use crate::integrator::Integrator;

/// `RenderParams::max_bounces` of a capture of three-bounce paths (spot, hidden point, sensed
/// point), the paths the band index's masses describe.
const THREE_BOUNCE_KERNEL_BOUNCES: u32 = 2;

/// The share of a render's time budget its target pilot may take. On the 327,680-triangle
/// sphere (confocal 16 x 16, 1,000 bins of 4 ps, without its band index) a 1 s capture had 1
/// sample per pixel after a whole pilot of 256 (0.6 s) and a variance 150 times that of one
/// with a pilot of 64 samples (15 % of the time; no pilot: 1.7 times).
const PILOT_BUDGET_SHARE: f64 = 0.125;

/// Samples per pixel of a pilot's passes under a time budget, between which it checks the
/// time.
const PILOT_PASS: u32 = 16;

impl BidirectionalTracer<'_> {
    /// Builds the band index (when one is still to be built) and binds queue_ellipsoid_queries
    /// to it; where its entries do not fit a binding, or its build would outlast the render's
    /// time budget, the capture goes on with BVH queries.
    pub(super) fn build_band_index(&mut self) -> Result<()> {
        let Some(index) = self.band_index.take() else { return Ok(()) };
        let visits_fit = self.visit_tables_fit();
        let wf = &mut self.wf;
        let result =
            match index.build(wf.ctx, &mut wf.resources, &mut wf.params, self.binding_limit, self.time_budget)? {
                Ok(summary) => Ok(summary),
                Err(stop) => {
                    if let crate::nlos::band_index::BuildStop::OutOfTime(_) = stop {
                        // A later render with a longer budget (or by samples) may build it.
                        self.band_index_deferred = Some(index);
                    }
                    Err(stop.why().to_owned())
                }
            };
        if let (Ok(_), Some(kernels), Some(groups)) =
            (&result, &self.stages.ellipsoidal, &mut self.bindings.ellipsoidal)
        {
            // queue_ellipsoid_queries reads the index.
            groups[1] = kernels[1].bind(wf.ctx, &wf.resources);
        }
        if let Ok(summary) = &result
            && visits_fit
        {
            let strata = wf.params.target_length.strata;
            let cells = (wf.params.width * wf.params.height) as usize * strata.div_ceil(summary.ratio) as usize;
            let bins: Vec<f32> = read_buffer(wf.ctx, wf.resources.get("band_sums").unwrap(), cells)?;
            self.band_masses = crate::nlos::band_index::strata_masses(&bins, summary.ratio, strata);
        }
        self.band_index_result = Some(result);
        Ok(())
    }

    /// Shares out the extra visits of each pixel's bins by the band index's masses
    /// (`film::target::visit_tables_from_masses`) when the index is in use, no allocation is,
    /// and the capture's paths are the three-bounce ones the masses describe (--max-bounces 3,
    /// which the kernels count as 2: to them the laser spot is a light, `kernel_bounces`;
    /// longer paths arrive later, where a pilot render sees them): the masses are exact where a
    /// pilot's transient is noisy, and cost no samples. Returns whether it did.
    pub(super) fn apply_band_allocation(&mut self) -> bool {
        let t = self.wf.params.target_length;
        if self.band_masses.is_empty()
            || t.band_index == 0
            || t.extra != 0
            || self.wf.params.max_bounces != THREE_BOUNCE_KERNEL_BOUNCES
            || self.band_masses.len() != (self.wf.params.width * self.wf.params.height) as usize * t.strata as usize
        {
            return false;
        }
        let (extra, rows) = crate::film::target::visit_tables_from_masses(&t, &self.band_masses);
        self.wf.params.target_length.extra = extra;
        self.wf.params.target_length.extra_stride = crate::film::target::golden_stride(extra);
        let ctx = self.wf.ctx;
        ctx.queue.write_buffer(self.wf.resources.get("target_visits").unwrap(), 0, bytemuck::cast_slice(&rows));
        ctx.queue.write_buffer(self.wf.resources.get("params").unwrap(), 0, bytemuck::bytes_of(&self.wf.params));
        self.wf.target_visits = rows;
        true
    }

    /// Traces the pilot render (stratified bins, each once a cycle), shares out the extra
    /// visits of each pixel's bins by its transient (`film::target::visit_tables`) and discards
    /// the pilot's film: the render's samples are independent of the pilot's, so its estimate
    /// stays unbiased whatever the allocation. Under a time budget the pilot ends once it has
    /// taken PILOT_BUDGET_SHARE of it (after a pass of PILOT_PASS samples per pixel at most); one
    /// that had no time for a pass leaves every bin its even share.
    pub(super) fn run_target_pilot(&mut self) -> Result<()> {
        self.target_pilot_pending = false;
        let start = std::time::Instant::now();
        let limit = self.time_budget.map(|seconds| seconds * PILOT_BUDGET_SHARE);
        let mut traced = 0;
        while traced < self.target_pilot_asked {
            if limit.is_some_and(|limit| start.elapsed().as_secs_f64() >= limit) {
                break;
            }
            let pass = if limit.is_some() { PILOT_PASS } else { u32::MAX };
            let n = (self.target_pilot_asked - traced).min(pass).min(self.samples_per_pass());
            self.render_pass(n)?;
            traced += n;
        }
        if traced == 0 {
            return Ok(());
        }
        let pilot = self.film()?;
        let t = self.wf.params.target_length;
        let (extra, rows) = crate::film::target::visit_tables(&t, &pilot.data, pilot.bins as usize);
        self.wf.params.target_length.extra = extra;
        self.wf.params.target_length.extra_stride = crate::film::target::golden_stride(extra);
        self.wf.ctx.queue.write_buffer(self.wf.resources.get("target_visits").unwrap(), 0, bytemuck::cast_slice(&rows));
        self.wf.target_visits = rows;
        // Writes the parameters with a new seed and the film's first sample.
        self.reset_film();
        self.target_pilot_traced = traced;
        Ok(())
    }

    /// Whether the render has a target pilot and the current gate's visit tables fit the buffer
    /// built for them.
    pub(super) fn target_pilot_fits(&self) -> bool {
        self.target_pilot_asked > 0 && self.visit_tables_fit()
    }

    /// Whether the render keeps visit tables and the current gate's (strata + 1 counts per
    /// pixel) fit the buffer built for them.
    pub(super) fn visit_tables_fit(&self) -> bool {
        let t = &self.wf.params.target_length;
        let bytes = (self.wf.params.width as u64 * self.wf.params.height as u64) * (t.strata as u64 + 1) * 4;
        let room = self.wf.resources.get("target_visits").map_or(0, |b| b.size());
        self.keeps_visit_tables && t.strata > 0 && bytes <= room
    }
}
