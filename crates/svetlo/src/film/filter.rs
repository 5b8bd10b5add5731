//! Pixel reconstruction filters (separable), with Mitsuba's default radii.

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Filter {
    /// Box of radius 0.5: each sample counts for its own pixel only.
    Box,
    /// Tent (triangle) of the given radius (Mitsuba default 1).
    Tent { radius: f32 },
    /// Gaussian with standard deviation `stddev`, truncated at 4 sigma (Mitsuba default 0.5).
    Gaussian { stddev: f32 },
}

impl Default for Filter {
    fn default() -> Self {
        Filter::Gaussian { stddev: 0.5 }
    }
}

impl Filter {
    pub fn radius(&self) -> f32 {
        match *self {
            Filter::Box => 0.5,
            Filter::Tent { radius } => radius,
            Filter::Gaussian { stddev } => 4.0 * stddev,
        }
    }

    /// One-dimensional filter weight at offset `x` from the pixel center.
    #[inline]
    pub fn eval(&self, x: f32) -> f32 {
        match *self {
            Filter::Box => {
                if (-0.5..0.5).contains(&x) {
                    1.0
                } else {
                    0.0
                }
            }
            Filter::Tent { radius } => (1.0 - x.abs() / radius).max(0.0),
            Filter::Gaussian { stddev } => {
                let r = 4.0 * stddev;
                let a = 1.0 / (2.0 * stddev * stddev);
                ((-a * x * x).exp() - (-a * r * r).exp()).max(0.0)
            }
        }
    }
}

/// A filter with its constants worked out once (a tile's many samples each evaluate it a few
/// times per axis): the same operations as [`Filter::eval`], so the same weights to the bit,
/// without a Gaussian's second `exp` per weight.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct FilterWeights {
    filter: Filter,
    /// The Gaussian's 1 / (2 sigma^2) and its value at the radius, subtracted from each weight.
    a: f32,
    floor: f32,
}

impl FilterWeights {
    pub(crate) fn new(filter: Filter) -> Self {
        let (a, floor) = match filter {
            Filter::Gaussian { stddev } => {
                let r = 4.0 * stddev;
                let a = 1.0 / (2.0 * stddev * stddev);
                (a, (-a * r * r).exp())
            }
            Filter::Box | Filter::Tent { .. } => (0.0, 0.0),
        };
        FilterWeights { filter, a, floor }
    }

    /// [`Filter::eval`].
    #[inline]
    pub(crate) fn eval(&self, x: f32) -> f32 {
        match self.filter {
            Filter::Gaussian { .. } => self.gaussian(x),
            f => f.eval(x),
        }
    }

    /// [`Self::eval`] of a Gaussian (`filter` must be one).
    #[inline]
    pub(crate) fn gaussian(&self, x: f32) -> f32 {
        ((-self.a * x * x).exp() - self.floor).max(0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The prepared weights are `eval`'s to the bit, across and past each filter's support.
    #[test]
    fn prepared_weights_are_eval_bit_for_bit() {
        for f in [Filter::Box, Filter::Tent { radius: 1.0 }, Filter::Tent { radius: 1.7 }, Filter::Gaussian { stddev: 0.5 }, Filter::Gaussian { stddev: 0.37 }]
        {
            let w = FilterWeights::new(f);
            for i in -3000..=3000 {
                let x = i as f32 * 1e-3 + 1e-4;
                assert_eq!(w.eval(x).to_bits(), f.eval(x).to_bits(), "{f:?} at {x}");
            }
        }
    }
}
