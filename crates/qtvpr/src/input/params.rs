//! The parameters of a request, checked and resolved in one place for every front end.
//!
//! A transfer takes [`Params`], an online state [`OnlineParams`], and a calibration
//! file stores [`Defaults`] for whoever uses it (semantics §12: its `params` are the
//! defaults of every front end, batch and online). Each front end passes what its user
//! gave, `None` for what was left out, to [`Params::resolve`] or
//! [`OnlineParams::resolve`] with the calibration's defaults; nothing else decides a
//! default or checks a parameter.
//!
//! An operation over a [`ScoreSource`](crate::ScoreSource) takes its parameters as
//! [`Options`], with an optional progress callback.

use std::ops::Range;

use crate::error::{Error, Result};
use crate::input::check_precision;

/// The paper gives no value of `k`; 10 is this project's default.
pub const DEFAULT_K: usize = 10;

/// The precision target when none is given: the paper's 100%.
pub const DEFAULT_PRECISION: f64 = 1.0;

/// The warm-up of an online state when none is given: none, every query is decided on
/// the queries it has (semantics §11).
pub const DEFAULT_MIN_WINDOW: usize = 1;

/// `k >= 1`.
fn check_k(k: usize) -> Result<()> {
    if k < 1 {
        return Err(Error::param("k", format!("must be >= 1, got {k}")));
    }
    Ok(())
}

/// A window (or segment) size of at least 1.
fn check_window(window: usize) -> Result<()> {
    if window < 1 {
        return Err(Error::param("window", format!("must be >= 1, got {window}")));
    }
    Ok(())
}

/// Defaults stored in a calibration file's `meta` `params`; each can be overridden by
/// its user. A calibration made from arrays has [`Defaults::default`].
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct Defaults {
    /// Calibration queries sampled per deployment query.
    pub k: usize,
    /// Precision target tau in (0, 1].
    pub precision: f64,
    /// Window (or segment) size; `None` when the file sets none.
    pub window: Option<usize>,
    /// The margin gate (semantics §13); [`Gate::None`] unless the file sets one.
    pub gate: Gate,
}

impl Default for Defaults {
    fn default() -> Self {
        Self {
            k: DEFAULT_K,
            precision: DEFAULT_PRECISION,
            window: None,
            gate: Gate::None,
        }
    }
}

impl Defaults {
    /// Check `k >= 1`, tau in (0, 1] and a window, if any, of at least 1.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the parameter.
    pub fn validate(&self) -> Result<()> {
        check_k(self.k)?;
        check_precision(self.precision)?;
        self.window.map_or(Ok(()), check_window)
    }

    /// These defaults with each value given replacing its own (`None`: keep it),
    /// validated: what a calibration saved again with new values stores.
    ///
    /// # Errors
    /// [`Defaults::validate`].
    pub fn resolve(
        &self,
        k: Option<usize>,
        precision: Option<f64>,
        window: Option<usize>,
        gate: Option<Gate>,
    ) -> Result<Defaults> {
        let defaults = Defaults {
            k: k.unwrap_or(self.k),
            precision: precision.unwrap_or(self.precision),
            window: window.or(self.window),
            gate: gate.unwrap_or(self.gate),
        };
        defaults.validate()?;
        Ok(defaults)
    }
}

/// Parameters of a transfer.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct Params {
    /// Calibration queries sampled per deployment query (clipped to |Qcal|); at least 1.
    pub k: usize,
    /// Precision target tau in (0, 1].
    pub precision: f64,
    /// Deployment queries per segment; `None` is one batch of all of them.
    pub segment_size: Option<usize>,
    /// The margin gate (semantics §13): with [`Gate::Margin`] the transfer also gives
    /// `m*` and every query's margin.
    pub gate: Gate,
}

impl Default for Params {
    fn default() -> Self {
        Self {
            k: DEFAULT_K,
            precision: DEFAULT_PRECISION,
            segment_size: None,
            gate: Gate::None,
        }
    }
}

impl Params {
    /// Check `k >= 1` and tau in (0, 1] (a segment size is checked against the number
    /// of deployment queries by the transfer).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the parameter.
    pub fn validate(&self) -> Result<()> {
        check_k(self.k)?;
        check_precision(self.precision)
    }

    /// Parameters from those given, each `None` taking the calibration's default (one
    /// left out never falls back to a library default while the file has a value),
    /// validated.
    ///
    /// # Errors
    /// [`Params::validate`].
    pub fn resolve(
        defaults: &Defaults,
        k: Option<usize>,
        precision: Option<f64>,
        segment_size: Option<usize>,
        gate: Option<Gate>,
    ) -> Result<Params> {
        let params = Params {
            k: k.unwrap_or(defaults.k),
            precision: precision.unwrap_or(defaults.precision),
            segment_size,
            gate: gate.unwrap_or(defaults.gate),
        };
        params.validate()?;
        Ok(params)
    }
}

/// Parameters of an [`Online`](crate::Online) state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OnlineParams {
    /// Calibration queries sampled per deployment query (clipped to |Qcal|); at least 1.
    pub k: usize,
    /// Precision target tau in (0, 1].
    pub precision: f64,
    /// Window size `m`: each query is thresholded on its last `m` queries; at least 1.
    pub window: usize,
    /// Warm-up: queries before the `min_window`-th are reject-all; in `1..=window`.
    pub min_window: usize,
    /// The margin gate (semantics §13).
    pub gate: Gate,
}

impl OnlineParams {
    /// Check `k >= 1`, precision in (0, 1], `window >= 1` and `1 <= min_window <= window`.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the parameter.
    pub fn validate(&self) -> Result<()> {
        check_k(self.k)?;
        check_precision(self.precision)?;
        check_window(self.window)?;
        if !(1..=self.window).contains(&self.min_window) {
            return Err(Error::param(
                "min window",
                format!(
                    "must be between 1 and the window ({}), got {}",
                    self.window, self.min_window
                ),
            ));
        }
        Ok(())
    }

    /// Parameters from those given, each `None` taking the calibration's default
    /// (`min_window`: [`DEFAULT_MIN_WINDOW`]), validated.
    ///
    /// # Errors
    /// No window given and none in `defaults` ([`Error::InvalidParameter`]: "window is
    /// not given and the calibration sets none"), or [`OnlineParams::validate`].
    pub fn resolve(
        defaults: &Defaults,
        k: Option<usize>,
        precision: Option<f64>,
        window: Option<usize>,
        min_window: Option<usize>,
        gate: Option<Gate>,
    ) -> Result<OnlineParams> {
        let window = window
            .or(defaults.window)
            .ok_or_else(|| Error::param("window", "is not given and the calibration sets none"))?;
        let params = OnlineParams {
            k: k.unwrap_or(defaults.k),
            precision: precision.unwrap_or(defaults.precision),
            window,
            min_window: min_window.unwrap_or(DEFAULT_MIN_WINDOW),
            gate: gate.unwrap_or(defaults.gate),
        };
        params.validate()?;
        Ok(params)
    }
}

/// An operation's parameters `P` ([`Params`] for a transfer,
/// [`Protocol`](crate::Protocol) for an evaluation, the range of queries for
/// [`Descriptors::similarity`](crate::Descriptors::similarity)), and an optional
/// progress callback.
///
/// Every operation takes `impl Into<Options<P>>`, so `&params` alone means no progress.
#[derive(Clone, Copy)]
pub struct Options<'p, P> {
    /// The operation's parameters.
    pub params: P,
    /// Called as `progress(done, total)` from the calling thread as the operation goes
    /// (for a progress bar); not at all when the input is rejected. Each operation
    /// says what it counts.
    pub progress: Option<&'p dyn Fn(usize, usize)>,
}

impl<'p, P> Options<'p, P> {
    /// `params`, without progress.
    pub fn new(params: P) -> Self {
        Self { params, progress: None }
    }

    /// The same options, calling `progress(done, total)`.
    #[must_use]
    pub fn progress(mut self, progress: &'p dyn Fn(usize, usize)) -> Self {
        self.progress = Some(progress);
        self
    }

    /// Report `done` of `total`.
    pub(crate) fn report(&self, done: usize, total: usize) {
        if let Some(progress) = self.progress {
            progress(done, total);
        }
    }
}

impl<P: Clone> From<&P> for Options<'_, P> {
    fn from(params: &P) -> Self {
        Self::new(params.clone())
    }
}

impl From<Range<usize>> for Options<'_, Range<usize>> {
    fn from(queries: Range<usize>) -> Self {
        Self::new(queries)
    }
}

impl<P: std::fmt::Debug> std::fmt::Debug for Options<'_, P> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Options")
            .field("params", &self.params)
            .field("progress", &self.progress.is_some())
            .finish()
    }
}

/// Whether decisions are gated on their margin.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Gate {
    /// Quantile transfer alone (the paper's method).
    #[default]
    None,
    /// Accept a best match only when its margin is at least the calibration's `m*` too.
    Margin,
}

impl Gate {
    /// Every gate, in the order help texts list them.
    pub const ALL: [Gate; 2] = [Gate::None, Gate::Margin];

    /// The name used on the command line, in files, in JSON and in Python.
    pub fn as_str(self) -> &'static str {
        match self {
            Gate::None => "none",
            Gate::Margin => "margin",
        }
    }

    /// Whether decisions are gated.
    pub fn is_on(self) -> bool {
        self != Gate::None
    }
}

impl std::fmt::Display for Gate {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl std::str::FromStr for Gate {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        Gate::ALL.into_iter().find(|g| g.as_str() == s).ok_or_else(|| {
            let names: Vec<&str> = Gate::ALL.iter().map(|g| g.as_str()).collect();
            Error::param("gate", format!("must be one of {}, got {s:?}", names.join(", ")))
        })
    }
}

#[cfg(feature = "serde")]
impl serde::Serialize for Gate {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> std::result::Result<S::Ok, S::Error> {
        serializer.serialize_str(self.as_str())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_files_values_are_the_defaults_and_each_given_one_overrides() {
        let file = Defaults {
            k: 3,
            precision: 0.9,
            window: Some(28),
            gate: Gate::None,
        };
        let p = Params::resolve(&file, None, None, Some(5), None).unwrap();
        assert_eq!((p.k, p.precision, p.segment_size), (3, 0.9, Some(5)));
        let p = Params::resolve(&file, Some(7), Some(1.0), None, None).unwrap();
        assert_eq!((p.k, p.precision, p.segment_size), (7, 1.0, None));
        let o = OnlineParams::resolve(&file, None, None, None, None, None).unwrap();
        assert_eq!((o.k, o.precision, o.window, o.min_window), (3, 0.9, 28, 1));
        let o = OnlineParams::resolve(&file, Some(1), Some(0.5), Some(4), Some(4), None).unwrap();
        assert_eq!((o.k, o.precision, o.window, o.min_window), (1, 0.5, 4, 4));
        assert_eq!(file.resolve(None, None, None, None).unwrap(), file);
        assert_eq!(file.resolve(Some(4), None, Some(2), None).unwrap().window, Some(2));
        // No file: the library's.
        let p = Params::resolve(&Defaults::default(), None, None, None, None).unwrap();
        assert_eq!(p, Params::default());
    }

    #[test]
    fn one_set_of_checks_and_messages() {
        let d = Defaults::default();
        let err = |r: Result<Params>| r.unwrap_err().to_string();
        assert_eq!(
            err(Params::resolve(&d, Some(0), None, None, None)),
            "k must be >= 1, got 0"
        );
        assert_eq!(
            err(Params::resolve(&d, None, Some(1.5), None, None)),
            "precision must be in (0, 1], got 1.5"
        );
        let online = |w, m| {
            OnlineParams::resolve(&d, None, None, w, m, None)
                .unwrap_err()
                .to_string()
        };
        assert_eq!(online(None, None), "window is not given and the calibration sets none");
        assert_eq!(online(Some(0), None), "window must be >= 1, got 0");
        assert_eq!(
            online(Some(3), Some(4)),
            "min window must be between 1 and the window (3), got 4"
        );
        assert_eq!(
            d.resolve(Some(0), None, None, None).unwrap_err().to_string(),
            "k must be >= 1, got 0"
        );
        assert_eq!(
            d.resolve(None, None, Some(0), None).unwrap_err().to_string(),
            "window must be >= 1, got 0"
        );
    }
}
