//! gatetrace: a physically based GPU renderer for time-of-flight cameras.
//!
//! Time is optical path length in metres (c = 1); a pixel measures
//! I = integral of W(|x|) f(x) over paths x, where W is the sensor's pathlength importance (the
//! gate). README.md is the user's guide; docs/gates.md holds the units and conventions, and
//! docs/design.md the architecture and the mathematics.
#![warn(missing_docs)]

pub mod bvh;
pub mod capture;
pub mod ellipsoid;
pub mod film;
pub mod frames;
pub mod gpu;
pub mod integrator;
pub mod nlos;
pub mod rng;
pub mod sampling;
pub mod scene;
pub mod units;
