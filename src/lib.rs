//! gatetrace: a physically based GPU renderer for time-of-flight cameras.
//!
//! Time is optical path length in metres (c = 1); a pixel measures
//! I = integral of W(|x|) f(x) over paths x, where W is the sensor's pathlength importance (the
//! gate). The README documents units, conventions and the architecture.
#![warn(missing_docs)]

pub mod bvh;
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
