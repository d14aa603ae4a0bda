//! `--method combined`: direct and ellipsoidal connections in one estimator. Each pixel sample
//! takes one sample of each family, a direct one (all (s, t) strategies) and an ellipsoidal
//! one (a vertex on a spheroid for each pair of subpath vertices, K connections per spheroid),
//! from two tracers with independent random streams. Each contribution is weighted by its
//! family's share of its path, a balance heuristic between the families whose approximation
//! of the ellipsoidal density is in shaders/lib/family_mis.wesl; within its family a
//! contribution keeps the weight it has there. The weights of every path sum to one over both
//! families, so the image, the sum of the two tracers' films, is an unbiased estimate (the
//! tests compare it with `path` and `direct`).
//!
//! Not yet: checkpoints, shards, NLOS captures and directional lights (refused with a clear
//! error).

use anyhow::{Result, bail};

use super::bidirectional::{Family, ellipsoidal_half_seed};
use super::{BidirectionalTracer, Integrator, RenderSettings, Wavefront, checkpoint};
use crate::film::Film;
use crate::gpu::GpuContext;
use crate::scene::PreparedScene;

/// The two halves of a combined render.
pub struct CombinedTracer<'a> {
    direct: BidirectionalTracer<'a>,
    ellipsoidal: BidirectionalTracer<'a>,
}

impl<'a> CombinedTracer<'a> {
    /// Builds both halves (`settings.method` is `combined`).
    pub fn new(ctx: &'a GpuContext, scene: &PreparedScene, settings: &RenderSettings) -> Result<Self> {
        super::bidirectional::check_settings(settings)?;
        let k = settings.connections_per_query;
        let half = |family: Family| {
            BidirectionalTracer::with_family(ctx, scene, &family.settings(settings), Some((family, k)))
        };
        Ok(Self { direct: half(Family::Direct)?, ellipsoidal: half(Family::Ellipsoidal)? })
    }

    fn unsupported(what: &str) -> anyhow::Error {
        anyhow::anyhow!("--method combined cannot {what} yet: use --method direct or ellipsoidal for that")
    }
}

impl Integrator for CombinedTracer<'_> {
    fn wavefront(&self) -> &Wavefront<'_> {
        self.direct.wavefront()
    }

    fn render_pass(&mut self, samples: u32) -> Result<()> {
        self.direct.render_pass(samples)?;
        self.ellipsoidal.render_pass(samples)
    }

    fn samples_per_pass(&self) -> u32 {
        self.direct.samples_per_pass().min(self.ellipsoidal.samples_per_pass())
    }

    fn reset_film(&mut self) {
        self.direct.reset_film();
        self.ellipsoidal.reset_film();
    }

    fn restart(&mut self, seed: u32) {
        self.direct.restart(seed);
        self.ellipsoidal.restart(ellipsoidal_half_seed(seed));
    }

    fn set_gate(&mut self, scene: &PreparedScene, settings: &RenderSettings) -> Result<bool> {
        let direct = Family::Direct.settings(settings);
        let ellipsoidal = Family::Ellipsoidal.settings(settings);
        Ok(self.direct.set_gate(scene, &direct)? && self.ellipsoidal.set_gate(scene, &ellipsoidal)?)
    }

    /// The sum of the two halves' estimates.
    fn film(&self) -> Result<Film> {
        let mut film = self.direct.film()?;
        let other = self.ellipsoidal.film()?;
        for (a, b) in film.data.iter_mut().zip(&other.data) {
            *a += b;
        }
        Ok(film)
    }

    fn truncated_traversals(&self) -> Result<u64> {
        Ok(self.direct.truncated_traversals()? + self.ellipsoidal.truncated_traversals()?)
    }

    fn stats_report(&self) -> Result<Option<String>> {
        let (d, e) = (self.direct.stats_report()?, self.ellipsoidal.stats_report()?);
        Ok(match (d, e) {
            (None, None) => None,
            (d, e) => {
                Some(format!("direct half:\n{}ellipsoidal half:\n{}", d.unwrap_or_default(), e.unwrap_or_default()))
            }
        })
    }

    fn samples_to_visit_every_bin(&self) -> Option<u64> {
        self.ellipsoidal.samples_to_visit_every_bin()
    }

    fn prepare(&mut self) -> Result<()> {
        self.direct.prepare()?;
        self.ellipsoidal.prepare()
    }

    fn save_state(&self) -> Result<checkpoint::RenderState> {
        Err(Self::unsupported("save its state (--checkpoint, --shard)"))
    }

    fn load_state(&mut self, _state: &checkpoint::RenderState) -> Result<()> {
        Err(Self::unsupported("resume (--resume)"))
    }

    fn skip_samples(&mut self, samples: u64) -> Result<()> {
        if samples > 0 {
            bail!(Self::unsupported("render a shard (--shard)"));
        }
        Ok(())
    }
}
