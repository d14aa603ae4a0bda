//! Value parsers of the command line's options: resolutions, pairs, points, shards, and the
//! methods (`--method`, by `Method::parse`).

use clap::ValueEnum as _;
use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
use gatetrace::integrator::Method;

/// Parses `--method`: a name `Method::parse` accepts, among the methods a command renders.
/// Another method is refused with the reason (the viewer renders progressively, so not auto
/// and combined, which decide from a pilot per render); anything else gets clap's own error,
/// with the possible values.
#[derive(Clone)]
pub struct MethodParser {
    /// The methods accepted.
    methods: &'static [Method],
    /// List the methods with their help (a long --help), or by name only.
    with_help: bool,
}

impl MethodParser {
    /// Every method, listed by name (render --method).
    pub const ALL: MethodParser = MethodParser {
        methods: &[Method::Path, Method::Direct, Method::Ellipsoidal, Method::Combined, Method::Auto],
        with_help: false,
    };
    /// The methods the viewer renders (its window's buttons), listed with their help.
    pub const VIEW: MethodParser =
        MethodParser { methods: &[Method::Path, Method::Direct, Method::Ellipsoidal], with_help: true };
}

impl TypedValueParser for MethodParser {
    type Value = Method;

    fn parse_ref(
        &self,
        cmd: &clap::Command,
        arg: Option<&clap::Arg>,
        value: &std::ffi::OsStr,
    ) -> Result<Method, clap::Error> {
        let pilot = match Method::parse(&value.to_string_lossy()) {
            Ok(method) if self.methods.contains(&method) => return Ok(method),
            Ok(Method::Auto) => "auto chooses a method per render from a pilot",
            Ok(Method::Combined) => "combined shares its samples between its halves after a pilot",
            // Anything else: clap's own error, with the possible values.
            _ => {
                let names = self.possible_values().into_iter().flatten();
                let name = PossibleValuesParser::new(names).parse_ref(cmd, arg, value)?;
                return Method::parse(&name)
                    .map_err(|e| clap::Error::raw(clap::error::ErrorKind::InvalidValue, e).with_cmd(cmd));
            }
        };
        let message = format!(
            "--method {}: {pilot}; the viewer renders progressively: start it with path, direct or ellipsoidal\n",
            value.to_string_lossy()
        );
        Err(clap::Error::raw(clap::error::ErrorKind::InvalidValue, message).with_cmd(cmd))
    }

    fn possible_values(&self) -> Option<Box<dyn Iterator<Item = PossibleValue> + '_>> {
        Some(Box::new(
            self.methods
                .iter()
                .filter_map(|m| m.to_possible_value())
                .map(|value| if self.with_help { value } else { value.help(None::<&'static str>) }),
        ))
    }
}

/// Parses a `clap::ValueEnum` as clap does, but lists its values by name only, so a command
/// whose other options have one-paragraph help keeps the short --help.
#[derive(Clone)]
pub struct NamesOnly<E>(std::marker::PhantomData<E>);

impl<E> NamesOnly<E> {
    pub fn new() -> Self {
        Self(std::marker::PhantomData)
    }
}

impl<E: clap::ValueEnum + Clone + Send + Sync + 'static> TypedValueParser for NamesOnly<E> {
    type Value = E;

    fn parse_ref(
        &self,
        cmd: &clap::Command,
        arg: Option<&clap::Arg>,
        value: &std::ffi::OsStr,
    ) -> Result<E, clap::Error> {
        clap::builder::EnumValueParser::<E>::new().parse_ref(cmd, arg, value)
    }

    fn possible_values(&self) -> Option<Box<dyn Iterator<Item = PossibleValue> + '_>> {
        Some(Box::new(
            E::value_variants()
                .iter()
                .filter_map(|v| v.to_possible_value())
                .map(|value| value.help(None::<&'static str>)),
        ))
    }
}

pub fn parse_point(s: &str) -> Result<glam::Vec3, String> {
    let bad = || format!("`{s}` is not X,Y,Z (three finite numbers in metres, e.g. -1.2,0,0.6)");
    let v: Vec<f32> = s.split(',').map(|c| c.trim().parse::<f32>().map_err(|_| bad())).collect::<Result<_, _>>()?;
    match v[..] {
        [x, y, z] if x.is_finite() && y.is_finite() && z.is_finite() => Ok(glam::Vec3::new(x, y, z)),
        _ => Err(bad()),
    }
}

pub fn parse_uv(s: &str) -> Result<glam::Vec2, String> {
    let bad = || format!("`{s}` is not U,V (two texture coordinates in [0, 1], e.g. 0.5,0.5)");
    let (u, v) = s.split_once(',').ok_or_else(bad)?;
    let (u, v) = (u.trim().parse::<f32>().map_err(|_| bad())?, v.trim().parse::<f32>().map_err(|_| bad())?);
    if !((0.0..=1.0).contains(&u) && (0.0..=1.0).contains(&v)) {
        return Err(bad());
    }
    Ok(glam::Vec2::new(u, v))
}

/// A Mitsuba scene parameter, NAME=VALUE (the name: letters, digits and underscores).
pub fn parse_define(s: &str) -> Result<(String, String), String> {
    let bad = || format!("`{s}` is not NAME=VALUE (a Mitsuba scene's parameter, e.g. spp=256)");
    let (name, value) = s.split_once('=').ok_or_else(bad)?;
    if name.is_empty() || !name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
        return Err(bad());
    }
    Ok((name.to_owned(), value.to_owned()))
}

pub fn parse_fog(s: &str) -> Result<gatetrace::scene::MediumDesc, String> {
    gatetrace::scene::MediumDesc::parse_fog(s).map_err(|e| format!("{e:#}"))
}

pub fn parse_strategy(s: &str) -> Result<(u32, u32), String> {
    parse_pair(s, "S,T")
}

pub fn parse_pixel(s: &str) -> Result<(u32, u32), String> {
    parse_pair(s, "X,Y")
}

pub fn parse_pair(s: &str, what: &str) -> Result<(u32, u32), String> {
    let bad = || format!("`{s}` is not {what} (two non-negative integers, e.g. 1,2)");
    let (a, b) = s.split_once(',').ok_or_else(bad)?;
    Ok((a.trim().parse().map_err(|_| bad())?, b.trim().parse().map_err(|_| bad())?))
}

pub fn parse_shard(s: &str) -> Result<(u32, u32), String> {
    let bad = || format!("`{s}` is not I/N (the shard index from 0 and the count, e.g. 0/4)");
    let (i, n) = s.split_once('/').ok_or_else(bad)?;
    let (i, n): (u32, u32) = (i.trim().parse().map_err(|_| bad())?, n.trim().parse().map_err(|_| bad())?);
    if n == 0 || i >= n {
        return Err(format!("shard {i}/{n}: give I/N with 0 <= I < N"));
    }
    Ok((i, n))
}

pub fn parse_resolution(s: &str) -> Result<(u32, u32), String> {
    let bad = || format!("`{s}` is not WIDTHxHEIGHT (e.g. 256x256)");
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(bad)?;
    let (w, h) = (w.trim().parse::<u32>().map_err(|_| bad())?, h.trim().parse::<u32>().map_err(|_| bad())?);
    if w == 0 || h == 0 || w > 16384 || h > 16384 {
        return Err(format!("resolution {w}x{h} must be between 1x1 and 16384x16384"));
    }
    Ok((w, h))
}
