//! GPU time per stage (`render --profile`): a timestamp query before and after every kernel
//! dispatch, resolved whenever the host waits for the device, summed per pipeline label (the
//! kernel's name, so profiler rows read like the stage tables of docs/pipeline.md). Needs the
//! device features TIMESTAMP_QUERY and TIMESTAMP_QUERY_INSIDE_PASSES (lavapipe has both).
//! On a GPU that overlaps consecutive dispatches, a stage's interval may include some of its
//! neighbour's work; lavapipe runs them one after another.

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};

use anyhow::{Context as _, Result, anyhow};

/// Timestamp pairs recorded between two waits; dispatches beyond it go uncounted (reported).
const CAPACITY: u32 = 2048;

/// Totals of one stage.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StageTime {
    /// GPU time summed over its dispatches (ns).
    pub nanoseconds: f64,
    /// Dispatches measured.
    pub dispatches: u64,
    /// GPU time of the first dispatch measured (ns). On lavapipe it includes compiling the
    /// kernel, which llvmpipe does at a kernel's first dispatch unless Mesa's shader cache
    /// holds it.
    pub first_nanoseconds: f64,
}

/// The timestamp queries and the per-stage sums.
pub struct Profiler {
    queries: wgpu::QuerySet,
    resolved: wgpu::Buffer,
    readback: wgpu::Buffer,
    /// Label of each recorded pair since the last collection.
    pending: Vec<String>,
    /// Nanoseconds per timestamp tick.
    period: f64,
    totals: BTreeMap<String, StageTime>,
    /// Dispatches that found no free query pair.
    missed: u64,
}

/// A profiler shared by the context and every kernel built on it.
pub type SharedProfiler = Arc<Mutex<Profiler>>;

impl Profiler {
    /// A profiler on `device`, or an error naming the missing feature.
    pub fn new(device: &wgpu::Device, queue: &wgpu::Queue) -> Result<Self> {
        let needed = wgpu::Features::TIMESTAMP_QUERY | wgpu::Features::TIMESTAMP_QUERY_INSIDE_PASSES;
        if !device.features().contains(needed) {
            return Err(anyhow!("--profile needs timestamp queries inside compute passes, which this device lacks"));
        }
        let bytes = 2 * CAPACITY as u64 * 8;
        let queries = device.create_query_set(&wgpu::QuerySetDescriptor {
            label: Some("profiler"),
            ty: wgpu::QueryType::Timestamp,
            count: 2 * CAPACITY,
        });
        let resolved = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("profiler_resolved"),
            size: bytes,
            usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let readback = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("profiler_readback"),
            size: bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        Ok(Self {
            queries,
            resolved,
            readback,
            pending: Vec::new(),
            period: queue.get_timestamp_period() as f64,
            totals: BTreeMap::new(),
            missed: 0,
        })
    }

    /// Writes the start timestamp of a dispatch of `label`; returns its pair, or None when the
    /// queries are full until the next collection.
    pub fn begin(&mut self, pass: &mut wgpu::ComputePass, label: &str) -> Option<u32> {
        let pair = self.pending.len() as u32;
        if pair >= CAPACITY {
            self.missed += 1;
            return None;
        }
        self.pending.push(label.to_owned());
        pass.write_timestamp(&self.queries, 2 * pair);
        Some(pair)
    }

    /// Writes the end timestamp of pair `pair`.
    pub fn end(&mut self, pass: &mut wgpu::ComputePass, pair: u32) {
        pass.write_timestamp(&self.queries, 2 * pair + 1);
    }

    /// Reads the recorded pairs back and adds them to the totals; call when every submission
    /// that wrote them has finished.
    pub fn collect(&mut self, device: &wgpu::Device, queue: &wgpu::Queue) -> Result<()> {
        let n = self.pending.len() as u32;
        if n == 0 {
            return Ok(());
        }
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("profiler") });
        encoder.resolve_query_set(&self.queries, 0..2 * n, &self.resolved, 0);
        encoder.copy_buffer_to_buffer(&self.resolved, 0, &self.readback, 0, 2 * n as u64 * 8);
        queue.submit([encoder.finish()]);
        let slice = self.readback.slice(..2 * n as u64 * 8);
        slice.map_async(wgpu::MapMode::Read, |_| {});
        device.poll(wgpu::PollType::wait_indefinitely()).context("GPU device lost while reading timestamps")?;
        {
            let view = slice.get_mapped_range().map_err(|e| anyhow!("cannot read timestamps back: {e:?}"))?;
            let ticks: &[u64] = bytemuck::cast_slice(&view);
            for (label, pair) in self.pending.iter().zip(ticks.chunks(2)) {
                let t = self.totals.entry(label.clone()).or_default();
                let nanoseconds = pair[1].saturating_sub(pair[0]) as f64 * self.period;
                if t.dispatches == 0 {
                    t.first_nanoseconds = nanoseconds;
                }
                t.nanoseconds += nanoseconds;
                t.dispatches += 1;
            }
        }
        self.readback.unmap();
        self.pending.clear();
        Ok(())
    }

    /// Sums per stage (pipeline label) so far.
    pub fn totals(&self) -> &BTreeMap<String, StageTime> {
        &self.totals
    }

    /// A table of the stages, longest first: total ms, share, dispatches, mean µs, and the
    /// first dispatch's µs; then the stages whose first dispatch stands out (compile_suspects).
    pub fn report(&self, adapter: &str) -> String {
        let all: f64 = self.totals.values().map(|t| t.nanoseconds).sum();
        let mut rows: Vec<(&String, &StageTime)> = self.totals.iter().collect();
        rows.sort_by(|a, b| b.1.nanoseconds.total_cmp(&a.1.nanoseconds));
        let mut out = format!(
            "GPU time per stage (timestamp queries around each dispatch) on {adapter}: {:.1} ms in all\n\
             stage                                   total ms   share  dispatches    mean us   first us\n",
            all / 1e6
        );
        for (label, t) in &rows {
            out += &format!(
                "{label:<38} {:>10.1} {:>6.1}% {:>11} {:>10.1} {:>10.1}\n",
                t.nanoseconds / 1e6,
                100.0 * t.nanoseconds / all.max(1e-9),
                t.dispatches,
                t.nanoseconds / 1e3 / t.dispatches.max(1) as f64,
                t.first_nanoseconds / 1e3
            );
        }
        let suspects: Vec<&str> =
            rows.iter().filter(|(_, t)| compile_suspect(t)).map(|(label, _)| label.as_str()).collect();
        if !suspects.is_empty() {
            out += &format!(
                "First dispatches far above the rest of their stage ({}): they likely include compiling \
                 the kernel (lavapipe compiles at a kernel's first dispatch unless Mesa's shader cache \
                 holds it). Render again for steady figures.\n",
                suspects.join(", ")
            );
        }
        if self.missed > 0 {
            out += &format!("({} dispatches were not measured: more than {CAPACITY} between waits)\n", self.missed);
        }
        out
    }
}

/// Whether a stage's first dispatch took over 50 ms and over 4x the mean of its later ones:
/// time that is not the kernel's steady cost.
pub fn compile_suspect(t: &StageTime) -> bool {
    if t.dispatches < 2 {
        return false;
    }
    let rest = (t.nanoseconds - t.first_nanoseconds) / (t.dispatches - 1) as f64;
    t.first_nanoseconds > 50e6 && t.first_nanoseconds > 4.0 * rest
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_first_dispatch_far_above_the_rest_is_a_compile_suspect() {
        let stage = |first_ms: f64, rest_ms: f64, dispatches: u64| StageTime {
            nanoseconds: (first_ms + rest_ms * (dispatches - 1) as f64) * 1e6,
            dispatches,
            first_nanoseconds: first_ms * 1e6,
        };
        assert!(compile_suspect(&stage(5000.0, 300.0, 6)));
        assert!(!compile_suspect(&stage(900.0, 300.0, 6)), "3x the rest is within a stage's spread");
        assert!(!compile_suspect(&stage(40.0, 1.0, 6)), "under 50 ms is no compilation worth a note");
        assert!(!compile_suspect(&stage(5000.0, 0.0, 1)), "one dispatch has no rest to compare");
    }
}
