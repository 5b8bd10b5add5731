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
