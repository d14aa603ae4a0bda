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

impl BidirectionalTracer<'_> {
    /// Builds the band index (when one is still to be built) and binds queue_ellipsoid_queries
    /// to it; where its entries do not fit a binding the capture goes on with BVH queries.
    pub(super) fn build_band_index(&mut self) -> Result<()> {
        let Some(index) = self.band_index.take() else { return Ok(()) };
        let visits_fit = self.visit_tables_fit();
        let wf = &mut self.wf;
        let result = index.build(wf.ctx, &mut wf.resources, &mut wf.params, self.binding_limit)?;
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
    /// stays unbiased whatever the allocation.
    pub(super) fn run_target_pilot(&mut self) -> Result<()> {
        self.target_pilot_pending = false;
        self.render_samples(self.target_pilot_spp as u64)?;
        let pilot = self.film()?;
        let t = self.wf.params.target_length;
        let (extra, rows) = crate::film::target::visit_tables(&t, &pilot.data, pilot.bins as usize);
        self.wf.params.target_length.extra = extra;
        self.wf.params.target_length.extra_stride = crate::film::target::golden_stride(extra);
        self.wf.ctx.queue.write_buffer(self.wf.resources.get("target_visits").unwrap(), 0, bytemuck::cast_slice(&rows));
        self.wf.target_visits = rows;
        // Writes the parameters with a new seed and the film's first sample.
        self.reset_film();
        self.target_pilot_ran = true;
        Ok(())
    }

    /// Whether the render has a target pilot and the current gate's visit tables fit the buffer
    /// built for them.
    pub(super) fn target_pilot_fits(&self) -> bool {
        self.target_pilot_spp > 0 && self.visit_tables_fit()
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
