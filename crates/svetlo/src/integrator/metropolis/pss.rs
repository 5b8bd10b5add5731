//! Primary sample space (Kelemen et al. 2002): a path is a function of a vector of uniform
//! numbers, and the Markov chain walks over that vector.
//!
//! Values are made lazily, when the path evaluation asks for them, so a chain never stores
//! more dimensions than its paths use. A small step moves each coordinate by a Gaussian of
//! standard deviation `sigma`, wrapped onto [0,1) (a symmetric proposal on the torus); a large
//! step draws every coordinate afresh. Coordinates not read in an iteration catch up when next
//! read: `n` pending small steps compose to one Gaussian step of deviation `sigma * sqrt(n)`,
//! and a coordinate older than the last accepted large step is drawn afresh. Rejection
//! restores the backup of every coordinate the proposal touched.
//!
//! Dimensions are grouped in interleaved streams (camera, light, connection for BDPT) so that
//! one subpath growing does not shift the coordinates the others read.

use crate::sampling::{Pcg32, Sampler};

#[derive(Clone, Copy, Debug, Default)]
struct Coordinate {
    value: f32,
    /// Iteration that last set `value`.
    modified: u64,
    backup_value: f32,
    backup_modified: u64,
}

#[derive(Clone, Debug)]
pub struct PssSampler {
    x: Vec<Coordinate>,
    rng: Pcg32,
    pub sigma: f32,
    pub large_step_probability: f32,
    iteration: u64,
    last_large_step: u64,
    large_step: bool,
    n_streams: usize,
    stream: usize,
    sample_index: usize,
}

/// Wrap onto [0, 1).
#[inline]
fn wrap(v: f32) -> f32 {
    let w = v - v.floor();
    if w >= 1.0 {
        0.0
    } else {
        w
    }
}

impl PssSampler {
    /// A sampler whose first evaluation is a large step (all coordinates uniform), for the
    /// bootstrap and for a chain's initial state.
    pub fn new(rng: Pcg32, sigma: f32, large_step_probability: f32, n_streams: usize) -> Self {
        PssSampler {
            x: Vec::new(),
            rng,
            sigma,
            large_step_probability,
            iteration: 0,
            last_large_step: 0,
            large_step: true,
            n_streams: n_streams.max(1),
            stream: 0,
            sample_index: 0,
        }
    }

    /// Continue with another random stream (after the bootstrap replay, so that chains that
    /// start from the same seed path diverge).
    pub fn set_rng(&mut self, rng: Pcg32) {
        self.rng = rng;
    }

    /// Begin a proposal: a large step with probability `large_step_probability`.
    pub fn start_iteration(&mut self) {
        self.iteration += 1;
        self.large_step = self.rng.next_f32() < self.large_step_probability;
        self.stream = 0;
        self.sample_index = 0;
    }

    pub fn is_large_step(&self) -> bool {
        self.large_step
    }

    /// Restart reading at the beginning of stream `s` (the same coordinates as last time).
    pub fn start_stream(&mut self, s: usize) {
        debug_assert!(s < self.n_streams);
        self.stream = s;
        self.sample_index = 0;
    }

    pub fn accept(&mut self) {
        if self.large_step {
            self.last_large_step = self.iteration;
        }
    }

    pub fn reject(&mut self) {
        for c in &mut self.x {
            if c.modified == self.iteration {
                c.value = c.backup_value;
                c.modified = c.backup_modified;
            }
        }
        self.iteration -= 1;
    }

    /// Number of coordinates made so far.
    pub fn dimensions(&self) -> usize {
        self.x.len()
    }

    fn gaussian(&mut self) -> f32 {
        // Box-Muller; 1 - u keeps the logarithm finite.
        let u1 = 1.0 - self.rng.next_f32();
        let u2 = self.rng.next_f32();
        (-2.0 * u1.ln()).sqrt() * (std::f32::consts::TAU * u2).cos()
    }

    fn get(&mut self, index: usize) -> f32 {
        if index >= self.x.len() {
            // A new dimension: the state never depended on it, so its value is uniform
            // (its stationary marginal) and it counts as up to date.
            let old = self.x.len();
            self.x.resize(index + 1, Coordinate::default());
            for i in old..=index {
                let v = self.rng.next_f32();
                self.x[i] = Coordinate { value: v, modified: self.iteration, backup_value: v, backup_modified: self.iteration };
            }
            return self.x[index].value;
        }
        let it = self.iteration;
        if self.x[index].modified == it {
            return self.x[index].value;
        }
        if self.x[index].modified < self.last_large_step {
            let v = self.rng.next_f32();
            let c = &mut self.x[index];
            c.value = v;
            c.modified = self.last_large_step;
        }
        {
            let c = &mut self.x[index];
            c.backup_value = c.value;
            c.backup_modified = c.modified;
        }
        let v = if self.large_step {
            self.rng.next_f32()
        } else {
            let n = (it - self.x[index].modified) as f32;
            let step = self.sigma * n.sqrt() * self.gaussian();
            wrap(self.x[index].value + step)
        };
        let c = &mut self.x[index];
        c.value = v;
        c.modified = it;
        v
    }
}

impl Sampler for PssSampler {
    fn start_pixel_sample(&mut self, _x: u32, _y: u32, _index: u32) {}
    fn next_1d(&mut self) -> f32 {
        let i = self.sample_index * self.n_streams + self.stream;
        self.sample_index += 1;
        self.get(i)
    }
    fn samples_per_pixel(&self) -> u32 {
        1
    }
    fn clone_box(&self) -> Box<dyn Sampler> {
        Box::new(self.clone())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read(s: &mut PssSampler, n: usize) -> Vec<f32> {
        s.start_stream(0);
        (0..n).map(|_| s.next_1d()).collect()
    }

    #[test]
    fn reject_restores_and_accept_keeps() {
        let mut s = PssSampler::new(Pcg32::new(3, 0), 0.05, 0.0, 1);
        let x0 = read(&mut s, 5);
        s.start_iteration();
        let y = read(&mut s, 5);
        assert_ne!(x0, y);
        s.reject();
        s.start_iteration();
        // Re-reading after a rejection starts from x0 again (one composite step away).
        let y2 = read(&mut s, 3);
        s.accept();
        s.start_iteration();
        let z = read(&mut s, 3);
        s.reject();
        s.start_iteration();
        let z2 = read(&mut s, 3);
        // Values are close to the accepted state, not to x0, for both proposals.
        for i in 0..3 {
            let d = |a: f32, b: f32| ((a - b).abs()).min(1.0 - (a - b).abs());
            assert!(d(z[i], y2[i]) < 0.5 && d(z2[i], y2[i]) < 0.5);
        }
        assert!(y2.iter().chain(&z).chain(&z2).all(|v| (0.0..1.0).contains(v)));
    }

    #[test]
    fn small_steps_are_symmetric_and_wrap() {
        // The displacement of a coordinate under a small step has mean 0 on the torus and the
        // requested deviation.
        let sigma = 0.02;
        let mut s = PssSampler::new(Pcg32::new(9, 1), sigma, 0.0, 1);
        let mut sum = 0.0f64;
        let mut sum2 = 0.0f64;
        let n = 20000;
        let mut prev = read(&mut s, 1)[0];
        for _ in 0..n {
            s.start_iteration();
            let v = read(&mut s, 1)[0];
            let mut d = v - prev;
            if d > 0.5 {
                d -= 1.0;
            } else if d < -0.5 {
                d += 1.0;
            }
            sum += d as f64;
            sum2 += (d * d) as f64;
            s.accept();
            prev = v;
        }
        let mean = sum / n as f64;
        let sd = (sum2 / n as f64 - mean * mean).sqrt();
        let se = sigma as f64 / (n as f64).sqrt();
        assert!(mean.abs() < 5.0 * se, "mean step {mean}");
        assert!((sd / sigma as f64 - 1.0).abs() < 0.05, "deviation {sd}");
    }

    #[test]
    fn large_step_renews_unread_coordinates_only_when_accepted() {
        let mut s = PssSampler::new(Pcg32::new(5, 2), 1e-6, 1.0, 1);
        let x0 = read(&mut s, 4);
        s.start_iteration();
        assert!(s.is_large_step());
        let _ = read(&mut s, 1);
        s.reject();
        s.large_step_probability = 0.0;
        s.start_iteration();
        let y = read(&mut s, 4);
        for i in 0..4 {
            assert!((y[i] - x0[i]).abs() < 1e-3 || (y[i] - x0[i]).abs() > 0.999);
        }
    }
}
