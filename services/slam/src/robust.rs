//! Robust kernels, applied by iteratively reweighted least squares: an edge whose squared
//! Mahalanobis error s = eᵀΩe is large gets a weight below 1 (GPS multipath jumps, wrong
//! loop closures).

use serde::{Deserialize, Serialize};

/// A robust kernel and its scale (in units of the Mahalanobis distance √s). In text (JSON,
/// TOML) its kernel is a field (`{"kernel": "cauchy", "c": 10.0}`); in binary formats that
/// do not describe themselves (postcard), an enum as serde writes one.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(remote = "Robust")]
pub enum Robust {
    /// Plain least squares.
    #[default]
    None,
    /// Quadratic up to `delta`, linear beyond.
    Huber {
        /// Where quadratic turns linear (Mahalanobis distance).
        delta: f64,
    },
    /// ρ(s) = c² log(1 + s/c²): outliers fade out.
    Cauchy {
        /// Scale c (Mahalanobis distance).
        c: f64,
    },
    /// Dynamic covariance scaling (Agarwal et al. 2013) with parameter φ.
    Dcs {
        /// φ (squared Mahalanobis distance).
        phi: f64,
    },
}

/// The text form: the kernel named by a field, which needs a self-describing format.
#[derive(Serialize, Deserialize)]
#[serde(tag = "kernel", rename_all = "snake_case", deny_unknown_fields)]
enum Tagged {
    None,
    Huber { delta: f64 },
    Cauchy { c: f64 },
    Dcs { phi: f64 },
}

impl From<Robust> for Tagged {
    fn from(r: Robust) -> Tagged {
        match r {
            Robust::None => Tagged::None,
            Robust::Huber { delta } => Tagged::Huber { delta },
            Robust::Cauchy { c } => Tagged::Cauchy { c },
            Robust::Dcs { phi } => Tagged::Dcs { phi },
        }
    }
}

impl From<Tagged> for Robust {
    fn from(t: Tagged) -> Robust {
        match t {
            Tagged::None => Robust::None,
            Tagged::Huber { delta } => Robust::Huber { delta },
            Tagged::Cauchy { c } => Robust::Cauchy { c },
            Tagged::Dcs { phi } => Robust::Dcs { phi },
        }
    }
}

impl Serialize for Robust {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        if s.is_human_readable() {
            Tagged::from(*self).serialize(s)
        } else {
            Robust::serialize(self, s)
        }
    }
}

impl<'de> Deserialize<'de> for Robust {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Robust, D::Error> {
        if d.is_human_readable() {
            Tagged::deserialize(d).map(Robust::from)
        } else {
            Robust::deserialize(d)
        }
    }
}

impl Robust {
    /// IRLS weight for squared Mahalanobis error `s`.
    pub fn weight(&self, s: f64) -> f64 {
        match *self {
            Robust::None => 1.0,
            Robust::Huber { delta } => {
                let d = s.sqrt();
                if d <= delta { 1.0 } else { delta / d }
            }
            Robust::Cauchy { c } => 1.0 / (1.0 + s / (c * c)),
            Robust::Dcs { phi } => {
                let scale = (2.0 * phi / (phi + s)).min(1.0);
                scale * scale
            }
        }
    }

    /// The kernel's cost ρ(s) (equal to s for plain least squares).
    pub fn cost(&self, s: f64) -> f64 {
        match *self {
            Robust::None => s,
            Robust::Huber { delta } => {
                let d = s.sqrt();
                if d <= delta {
                    s
                } else {
                    2.0 * delta * d - delta * delta
                }
            }
            Robust::Cauchy { c } => c * c * (1.0 + s / (c * c)).ln(),
            Robust::Dcs { phi } => {
                let scale = (2.0 * phi / (phi + s)).min(1.0);
                scale * scale * s
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weights_are_one_for_inliers_and_shrink_for_outliers() {
        for k in [
            Robust::Huber { delta: 2.0 },
            Robust::Cauchy { c: 2.0 },
            Robust::Dcs { phi: 4.0 },
        ] {
            assert!((k.weight(0.01) - 1.0).abs() < 0.01, "{k:?}");
            assert!(k.weight(400.0) < 0.2, "{k:?}");
            assert!(k.cost(400.0) < 400.0, "{k:?}");
        }
        assert_eq!(Robust::None.weight(1e6), 1.0);
    }
}
