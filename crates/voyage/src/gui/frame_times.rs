//! The window's frame times: wall time per frame, the view's render time, and the
//! process's CPU time per frame (on a CPU Vulkan driver the work per frame, steadier than the
//! wall time on a busy machine). The last 240 frames count; beside them, every frame drawn
//! while the automatic flight played (the figure along a whole flight).

use std::collections::VecDeque;
use std::time::Instant;

use serde::Serialize;

const KEPT: usize = 240;

#[derive(Default)]
pub struct FrameTimes {
    frame_ms: VecDeque<f64>,
    render_ms: VecDeque<f64>,
    /// The process's CPU time (all threads) at each frame in `frame_ms`, ms.
    cpu_at_frame_ms: VecDeque<f64>,
    last_frame: Option<Instant>,
    /// Every frame that began with the automatic flight playing, ms.
    flying_ms: Vec<f64>,
    last_flying: bool,
}

/// What the report says of the frames.
#[derive(Serialize)]
pub struct FrameSummary {
    pub mean: f64,
    pub median: f64,
    pub p95: f64,
    pub frames: usize,
    pub fps: f64,
    /// CPU ms per frame (Linux only).
    pub cpu_ms: Option<f64>,
}

impl FrameTimes {
    /// A frame starts at `now`, `flying` or not: the time since the last one (None for the
    /// first) is recorded and returned, in seconds.
    pub fn tick(&mut self, now: Instant, flying: bool) -> Option<f64> {
        let since = self.last_frame.map(|t| now.duration_since(t).as_secs_f64());
        if let Some(s) = since {
            push_limited(&mut self.frame_ms, s * 1e3);
            if self.last_flying {
                self.flying_ms.push(s * 1e3);
            }
            if let Some(cpu) = process_cpu_ms() {
                push_limited(&mut self.cpu_at_frame_ms, cpu);
            }
        }
        self.last_frame = Some(now);
        self.last_flying = flying;
        since
    }

    pub fn record_render(&mut self, ms: f64) {
        push_limited(&mut self.render_ms, ms);
    }

    pub fn last_frame_ms(&self) -> f64 {
        self.frame_ms.back().copied().unwrap_or(0.0)
    }

    pub fn mean_render_ms(&self) -> f64 {
        mean(&self.render_ms)
    }

    pub fn summary(&self) -> FrameSummary {
        let mut s = summarize(self.frame_ms.iter().copied().collect());
        s.cpu_ms = cpu_per_frame(&self.cpu_at_frame_ms);
        s
    }

    /// The frames drawn while the automatic flight played (no CPU figure).
    pub fn flying(&self) -> FrameSummary {
        summarize(self.flying_ms.clone())
    }
}

/// Mean, median and 95th percentile of frame times (ms).
fn summarize(mut sorted: Vec<f64>) -> FrameSummary {
    sorted.sort_by(f64::total_cmp);
    let pct = |q: f64| {
        sorted
            .get(((sorted.len() as f64 - 1.0) * q).round() as usize)
            .copied()
            .unwrap_or(0.0)
    };
    let m = if sorted.is_empty() {
        0.0
    } else {
        sorted.iter().sum::<f64>() / sorted.len() as f64
    };
    FrameSummary {
        mean: m,
        median: pct(0.5),
        p95: pct(0.95),
        frames: sorted.len(),
        fps: if m > 0.0 { 1000.0 / m } else { 0.0 },
        cpu_ms: None,
    }
}

fn mean(v: &VecDeque<f64>) -> f64 {
    if v.is_empty() {
        0.0
    } else {
        v.iter().sum::<f64>() / v.len() as f64
    }
}

/// User + system time of this process so far (Linux's /proc; its clock ticks are 1/100 s).
fn process_cpu_ms() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // The fields after the command name, which is in parentheses and may hold spaces.
    let rest = &stat[stat.rfind(')')? + 1..];
    let mut fields = rest.split_whitespace().skip(11);
    let (utime, stime): (f64, f64) = (fields.next()?.parse().ok()?, fields.next()?.parse().ok()?);
    Some((utime + stime) * 10.0)
}

/// Mean CPU ms per frame over the frames `cumulative` covers.
fn cpu_per_frame(cumulative: &VecDeque<f64>) -> Option<f64> {
    let (first, last) = (cumulative.front()?, cumulative.back()?);
    (cumulative.len() > 1).then(|| (last - first) / (cumulative.len() - 1) as f64)
}

fn push_limited(v: &mut VecDeque<f64>, x: f64) {
    if v.len() >= KEPT {
        v.pop_front();
    }
    v.push_back(x);
}
