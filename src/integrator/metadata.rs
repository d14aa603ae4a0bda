//! What a render's outputs record about it: the metadata of the command line's outputs and the
//! Python package's renders.

use std::path::Path;

use serde_json::json;

use super::{Method, RenderOutput, RenderSettings};
use crate::film::output::Metadata;
use crate::gpu::GpuContext;

/// Seconds rounded to milliseconds, as metadata records them.
pub fn milli(seconds: f64) -> serde_json::Value {
    ((seconds * 1e3).round() / 1e3).into()
}

/// What every output records about its render (scene, settings, timing, device), as the
/// command line's outputs and the Python package give it: (key, typed value) pairs in order.
pub fn render_metadata(
    ctx: &GpuContext,
    scene_path: &Path,
    gate_spec: &str,
    settings: &RenderSettings,
    output: &RenderOutput,
) -> Metadata {
    let film = &output.film;
    let secs = output.elapsed.as_secs_f64();
    let gate = &settings.gate;
    let mut metadata: Metadata = vec![
        ("scene".into(), scene_path.display().to_string().into()),
        ("method".into(), settings.method.name().into()),
        ("gate".into(), gate_spec.into()),
        ("gate_parameters".into(), gate.parameters()),
        ("gate_description".into(), gate.describe().into()),
        ("spp".into(), film.spp.into()),
        ("seed".into(), settings.seed.into()),
        ("max_bounces".into(), settings.max_bounces.into()),
        ("rr_depth".into(), settings.rr_depth.into()),
        ("resolution".into(), json!([settings.width, settings.height])),
        ("elapsed_seconds".into(), milli(secs)),
        ("rendering_seconds".into(), milli(output.rendering.as_secs_f64())),
        ("adapter".into(), ctx.adapter_description().into()),
        ("truncated_traversals".into(), output.truncated_traversals.into()),
        (
            "units".into(),
            "bin-integrated radiance W m^-2 sr^-1 weighted by W; lengths are optical path in metres; resolution is \
             [width, height] in pixels; rr_depth null means Russian roulette is off"
                .into(),
        ),
        ("gatetrace_version".into(), env!("CARGO_PKG_VERSION").into()),
    ];
    if let Some((s, t)) = settings.debug_strategy {
        metadata.push(("debug_strategy".into(), json!([s, t])));
    }
    if let Some(allocation) = &output.allocation {
        metadata.push(("combined_renders".into(), allocation.renders().into()));
        if allocation.alone.is_none() {
            metadata.push(("ellipsoidal_share".into(), allocation.ellipsoidal_share.into()));
        }
        metadata.push(("combined_allocation".into(), allocation.reason.clone().into()));
    }
    if let Some(roulette) = &output.roulette {
        metadata.push(("query_roulette".into(), (roulette.probability as f64).into()));
        metadata.push(("query_roulette_reason".into(), roulette.reason.clone().into()));
    }
    if let Some(choice) = &output.choice {
        metadata.push(("chosen_method".into(), choice.chosen.name().into()));
        metadata.push(("auto_reason".into(), choice.reason.clone().into()));
        for c in &choice.candidates {
            metadata.push((
                format!("auto_pilot_{}", c.method.name()),
                json!({
                    "spp": c.spp,
                    "resolution": [choice.pilot_resolution.0, choice.pilot_resolution.1],
                    "seconds": c.seconds,
                    "seconds_per_sample": c.pilot_seconds_per_sample,
                    "variance_per_sample": c.variance_per_sample,
                    "variance_seconds_per_sample": c.cost(),
                }),
            ));
        }
    }
    if matches!(settings.method, Method::Direct | Method::Combined | Method::Auto) {
        metadata.push(("camera_pilot_spp".into(), output.camera_pilot_spp.into()));
    }
    if matches!(settings.method, Method::Ellipsoidal | Method::Auto) {
        let g = settings.ellipsoid_guards;
        metadata.push(("connections_per_query".into(), settings.connections_per_query.into()));
        metadata.push(("query_split".into(), settings.query.split.into()));
        metadata.push(("query_tree".into(), if settings.query.wide { "wide" } else { "binary" }.into()));
        metadata.push((
            "query_weights".into(),
            if settings.query.reflection_weights { "reflection" } else { "arcs" }.into(),
        ));
        metadata.push(("ellipsoid_guards".into(), json!({ "needle": g.needle, "length": g.length })));
        metadata.push(("target_pilot_spp".into(), output.target_pilot_spp.into()));
        if let Some(report) = &output.band_index {
            metadata.push(("band_index".into(), report.clone().into()));
        }
    }
    metadata
}
