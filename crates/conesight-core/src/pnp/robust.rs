//! Robust losses for iteratively reweighted least squares (IRLS).
//!
//! Each loss is a function rho(r) of a residual norm r (pixels); IRLS minimises
//! sum rho(r_i) by solving weighted least squares with weights w(r) = rho'(r) / r.

use serde::{Deserialize, Serialize};

/// A robust loss on a residual norm in pixels.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum RobustLoss {
    /// Plain least squares, rho(r) = r^2 / 2 (no outlier resistance).
    Squared,
    /// Huber: quadratic below `scale_px`, linear above.
    Huber {
        /// Residual norm (pixels) where the loss turns linear.
        scale_px: f64,
    },
    /// Cauchy (Lorentzian): rho(r) = c^2 / 2 ln(1 + (r / c)^2); large residuals have
    /// vanishing influence.
    Cauchy {
        /// Scale c in pixels: a residual of c gets weight 1/2.
        scale_px: f64,
    },
}

impl RobustLoss {
    /// The IRLS weight w(r) = rho'(r) / r for a residual norm `residual_px` (>= 0).
    pub fn weight(&self, residual_px: f64) -> f64 {
        match *self {
            Self::Squared => 1.0,
            Self::Huber { scale_px } => {
                if residual_px <= scale_px {
                    1.0
                } else {
                    scale_px / residual_px
                }
            }
            Self::Cauchy { scale_px } => {
                let ratio = residual_px / scale_px;
                1.0 / (1.0 + ratio * ratio)
            }
        }
    }

    /// The loss rho(r) for a residual norm `residual_px` (>= 0).
    pub fn cost(&self, residual_px: f64) -> f64 {
        match *self {
            Self::Squared => 0.5 * residual_px * residual_px,
            Self::Huber { scale_px } => {
                if residual_px <= scale_px {
                    0.5 * residual_px * residual_px
                } else {
                    scale_px * (residual_px - 0.5 * scale_px)
                }
            }
            Self::Cauchy { scale_px } => {
                let ratio = residual_px / scale_px;
                0.5 * scale_px * scale_px * (ratio * ratio).ln_1p()
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn weights_are_the_derivative_over_the_residual() {
        let h = 1e-6;
        for loss in [
            RobustLoss::Squared,
            RobustLoss::Huber { scale_px: 1.5 },
            RobustLoss::Cauchy { scale_px: 2.0 },
        ] {
            for r in [0.3, 1.0, 2.5, 10.0, 40.0] {
                let derivative = (loss.cost(r + h) - loss.cost(r - h)) / (2.0 * h);
                assert_relative_eq!(loss.weight(r), derivative / r, max_relative = 1e-6);
            }
        }
    }

    #[test]
    fn cauchy_suppresses_large_residuals_more_than_huber() {
        let huber = RobustLoss::Huber { scale_px: 2.0 };
        let cauchy = RobustLoss::Cauchy { scale_px: 2.0 };
        assert_eq!(huber.weight(1.0), 1.0);
        assert!(cauchy.weight(20.0) < huber.weight(20.0) / 5.0);
        assert!(cauchy.weight(20.0) < 0.01);
    }
}
