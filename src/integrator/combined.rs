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

use anyhow::{Result, bail, ensure};

use super::{BidirectionalTracer, Integrator, Method, RenderSettings, Wavefront, checkpoint};
use crate::film::Film;
use crate::gpu::GpuContext;
use crate::scene::PreparedScene;

/// Which half of a combined render a tracer is: its connection kernels weigh each contribution
/// by their family's share of the path (shaders/lib/family_mis.wesl).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Family {
    /// connect_direct's strategies.
    Direct = 1,
    /// connect_ellipsoidal's and connect_spherical's.
    Ellipsoidal = 2,
}

impl Family {
    /// The settings of this half of the combined render `settings`: its method, one connection
    /// per strategy for the direct half, and for the ellipsoidal half a seed of its own, so its
    /// subpaths are independent of the direct half's.
    pub fn settings(self, settings: &RenderSettings) -> RenderSettings {
        match self {
            Family::Direct => RenderSettings { method: Method::Direct, connections_per_query: 1, ..settings.clone() },
            Family::Ellipsoidal => RenderSettings {
                method: Method::Ellipsoidal,
                seed: ellipsoidal_half_seed(settings.seed),
                ..settings.clone()
            },
        }
    }
}

/// The seed of a combined render's ellipsoidal half, given the render's.
fn ellipsoidal_half_seed(seed: u32) -> u32 {
    seed ^ 0x5bd1_e995
}

/// Errors for settings `combined` cannot render (checked before any work): both halves must be
/// valid, and a combined render has no captures and no debug strategy yet.
pub fn check_settings(settings: &RenderSettings) -> Result<()> {
    ensure!(
        !matches!(settings.gate, crate::film::Gate::None),
        "--method combined weighs direct and ellipsoidal connections against each other and needs a gate (box, \
         gaussian, cw, table or transient); without one use --method path or direct"
    );
    ensure!(settings.nlos.is_none(), "--method combined does not render --nlos captures yet: use --method ellipsoidal");
    ensure!(settings.debug_strategy.is_none(), "--debug-strategy needs --method direct");
    for role in [Family::Direct, Family::Ellipsoidal] {
        super::bidirectional::check_settings(&role.settings(settings))?;
    }
    Ok(())
}

/// The two halves of a combined render.
pub struct CombinedTracer<'a> {
    direct: BidirectionalTracer<'a>,
    ellipsoidal: BidirectionalTracer<'a>,
}

impl<'a> CombinedTracer<'a> {
    /// Builds both halves (`settings.method` is `combined`).
    pub fn new(ctx: &'a GpuContext, scene: &PreparedScene, settings: &RenderSettings) -> Result<Self> {
        check_settings(settings)?;
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
