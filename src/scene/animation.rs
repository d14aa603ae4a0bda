//! glTF node animations sampled at one time of the animation clock: the local transforms of the
//! animated nodes (translation, rotation, scale), which the loader then bakes into the
//! triangles, lights and camera as for a static scene. Every animation of the file plays on the
//! same clock; before its first key a channel holds its first value, after its last key its
//! last. STEP, LINEAR (slerp for rotations) and CUBICSPLINE interpolation, as the glTF 2.0
//! specification defines them.

use std::collections::HashMap;

use anyhow::{Result, anyhow, bail, ensure};
use glam::{Mat4, Quat, Vec3, Vec4};
use gltf::animation::{Interpolation, Property, util::ReadOutputs};

/// Local transforms (node index -> matrix) of every animated node at `time` (s).
pub fn sample_animations(
    name: &str,
    doc: &gltf::Document,
    buffers: &[gltf::buffer::Data],
    time: f64,
) -> Result<HashMap<usize, Mat4>> {
    ensure!(time.is_finite(), "{name}: animation time {time} s is not finite");
    let mut trs: HashMap<usize, (Vec3, Quat, Vec3)> = HashMap::new();
    let mut animated = false;
    for animation in doc.animations() {
        let anim_name =
            animation.name().map(|n| format!("animation `{n}`")).unwrap_or(format!("animation {}", animation.index()));
        for channel in animation.channels() {
            animated = true;
            let what = format!("{name}: {anim_name}, channel {}", channel.index());
            check_channel(doc, animation.index(), &channel).map_err(|e| anyhow!("{what}: {e}"))?;
            let node = channel.target().node();
            let reader = channel.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
            let times: Vec<f32> =
                reader.read_inputs().ok_or_else(|| anyhow!("{what}: cannot read the key times"))?.collect();
            ensure!(!times.is_empty(), "{what}: no keys");
            ensure!(
                times.iter().all(|t| t.is_finite()) && times.windows(2).all(|w| w[1] > w[0]),
                "{what}: key times must be finite and strictly increasing"
            );
            let outputs: Vec<Vec4> =
                match reader.read_outputs().ok_or_else(|| anyhow!("{what}: cannot read the key values"))? {
                    ReadOutputs::Translations(it) | ReadOutputs::Scales(it) => {
                        it.map(|v| Vec3::from(v).extend(0.0)).collect()
                    }
                    ReadOutputs::Rotations(r) => r.into_f32().map(Vec4::from).collect(),
                    ReadOutputs::MorphTargetWeights(_) => {
                        bail!("{what}: morph-target animations are not supported (only translation, rotation, scale)")
                    }
                };
            let interpolation = channel.sampler().interpolation();
            let per_key = if interpolation == Interpolation::CubicSpline { 3 } else { 1 };
            ensure!(
                outputs.len() == per_key * times.len(),
                "{what}: {} values for {} keys (expected {})",
                outputs.len(),
                times.len(),
                per_key * times.len()
            );
            ensure!(outputs.iter().all(|v| v.is_finite()), "{what}: non-finite key values");
            let rotation = channel.target().property() == Property::Rotation;
            let value = sample(&times, &outputs, interpolation, time as f32, rotation);
            let entry = trs.entry(node.index()).or_insert_with(|| {
                let (t, r, s) = node.transform().decomposed();
                (Vec3::from(t), Quat::from_array(r), Vec3::from(s))
            });
            match channel.target().property() {
                Property::Translation => entry.0 = value.truncate(),
                Property::Rotation => {
                    ensure!(value.length() > 0.0, "{what}: zero rotation quaternion at {time} s");
                    entry.1 = Quat::from_vec4(value).normalize();
                }
                Property::Scale => entry.2 = value.truncate(),
                Property::MorphTargetWeights => unreachable!("rejected above"),
            }
        }
    }
    ensure!(animated, "{name}: --anim-time given, but the file has no animation");
    Ok(trs.into_iter().map(|(node, (t, r, s))| (node, Mat4::from_scale_rotation_translation(s, r, t))).collect())
}

/// Checks what the glTF reader would otherwise unwrap or reinterpret: the channel's target path
/// and interpolation are known names, its key times are floats (SCALAR) and its values have
/// the types glTF 2.0 requires of its path.
fn check_channel(doc: &gltf::Document, animation: usize, channel: &gltf::animation::Channel) -> Result<()> {
    use gltf::accessor::{DataType as D, Dimensions};
    use gltf::json::validation::Checked;
    let json = &doc.as_json().animations[animation];
    let channel_json = &json.channels[channel.index()];
    let Checked::Valid(property) = channel_json.target.path else {
        bail!("the target path is not translation, rotation, scale or weights");
    };
    let sampler =
        json.samplers.get(channel_json.sampler.value()).ok_or_else(|| anyhow!("its sampler does not exist"))?;
    if !matches!(sampler.interpolation, Checked::Valid(_)) {
        bail!("the interpolation is not LINEAR, STEP or CUBICSPLINE");
    }
    let root = doc.as_json();
    ensure!(
        channel_json.target.node.value() < root.nodes.len(),
        "its target node {} does not exist",
        channel_json.target.node.value()
    );
    for (role, accessor) in [("key times", sampler.input), ("key values", sampler.output)] {
        ensure!(
            accessor.value() < root.accessors.len(),
            "the accessor {} of its {role} does not exist",
            accessor.value()
        );
    }
    let (input, output) = (channel.sampler().input(), channel.sampler().output());
    ensure!(
        input.dimensions() == Dimensions::Scalar && input.data_type() == D::F32,
        "key times (accessor {}) must be SCALAR of float",
        input.index()
    );
    let ok = match property {
        Property::Translation | Property::Scale => {
            output.dimensions() == Dimensions::Vec3 && output.data_type() == D::F32
        }
        Property::Rotation => {
            output.dimensions() == Dimensions::Vec4
                && (output.data_type() == D::F32
                    || (output.normalized() && matches!(output.data_type(), D::I8 | D::U8 | D::I16 | D::U16)))
        }
        Property::MorphTargetWeights => true,
    };
    ensure!(
        ok,
        "key values (accessor {}) have the wrong type for {property:?}: glTF 2.0 requires VEC3 of float for \
         translation and scale, VEC4 of float or normalised integers for rotation",
        output.index()
    );
    Ok(())
}

/// The value of one channel at time t: keys `times`, values `values` (three per key for
/// CUBICSPLINE: in-tangent, value, out-tangent). Rotations are unit quaternions (x, y, z, w).
pub fn sample(times: &[f32], values: &[Vec4], interpolation: Interpolation, t: f32, rotation: bool) -> Vec4 {
    let n = times.len();
    let key = |i: usize| if interpolation == Interpolation::CubicSpline { values[3 * i + 1] } else { values[i] };
    if t <= times[0] {
        return key(0);
    }
    if t >= times[n - 1] {
        return key(n - 1);
    }
    // times[i] <= t < times[i + 1]
    let i = times.partition_point(|&k| k <= t) - 1;
    let dt = times[i + 1] - times[i];
    let s = (t - times[i]) / dt;
    match interpolation {
        Interpolation::Step => key(i),
        Interpolation::Linear if rotation => {
            let (a, b) = (Quat::from_vec4(key(i)).normalize(), Quat::from_vec4(key(i + 1)).normalize());
            Vec4::from(a.slerp(b, s))
        }
        Interpolation::Linear => key(i).lerp(key(i + 1), s),
        Interpolation::CubicSpline => {
            let (v0, b0) = (values[3 * i + 1], values[3 * i + 2]);
            let (a1, v1) = (values[3 * (i + 1)], values[3 * (i + 1) + 1]);
            let (s2, s3) = (s * s, s * s * s);
            let p = (2.0 * s3 - 3.0 * s2 + 1.0) * v0
                + (s3 - 2.0 * s2 + s) * dt * b0
                + (-2.0 * s3 + 3.0 * s2) * v1
                + (s3 - s2) * dt * a1;
            if rotation { p.normalize() } else { p }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn linear_keys_interpolate_and_clamp() {
        let times = [0.0, 1.0, 3.0];
        let values = [Vec4::ZERO, Vec4::new(2.0, 0.0, 0.0, 0.0), Vec4::new(2.0, 4.0, 0.0, 0.0)];
        let at = |t| sample(&times, &values, Interpolation::Linear, t, false);
        assert_eq!(at(-1.0), values[0]);
        assert_eq!(at(0.5), Vec4::new(1.0, 0.0, 0.0, 0.0));
        assert_eq!(at(2.0), Vec4::new(2.0, 2.0, 0.0, 0.0));
        assert_eq!(at(5.0), values[2]);
        assert_eq!(sample(&times, &values, Interpolation::Step, 2.9, false), values[1]);
    }

    #[test]
    fn rotations_slerp_at_constant_speed() {
        let a = Quat::IDENTITY;
        let b = Quat::from_rotation_y(std::f32::consts::FRAC_PI_2);
        let q = Quat::from_vec4(sample(&[0.0, 1.0], &[Vec4::from(a), Vec4::from(b)], Interpolation::Linear, 0.5, true));
        assert!(q.angle_between(Quat::from_rotation_y(std::f32::consts::FRAC_PI_4)) < 1e-5);
    }

    #[test]
    fn cubic_splines_pass_through_their_keys_with_their_tangents() {
        // x(t) = t^3 on [0, 2]: keys at 0, 1, 2 with tangents 3 t^2.
        let key = |t: f32| [Vec4::splat(3.0 * t * t), Vec4::splat(t * t * t), Vec4::splat(3.0 * t * t)];
        let values: Vec<Vec4> = [0.0, 1.0, 2.0].into_iter().flat_map(key).collect();
        for t in [0.0f32, 0.25, 0.5, 1.0, 1.7, 2.0] {
            let x = sample(&[0.0, 1.0, 2.0], &values, Interpolation::CubicSpline, t, false).x;
            assert!((x - t * t * t).abs() < 1e-5, "t {t}: {x}");
        }
    }
}
