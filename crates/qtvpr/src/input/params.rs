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
//!
//! The gates a request enables are one [`Gate`] (a set of them, by name), and the
//! sequence gate's parameters one [`SequenceParams`] (with its [`Line`], the agreement
//! of semantics §15 and §16), defined here beside the other parameters so that every
//! request holds them; what they mean is in `gates/sequence.rs` and
//! `rules/agreement.rs`.

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
    /// The gates (semantics §13, §15); [`Gate::None`] unless the file sets them.
    pub gate: Gate,
    /// The sequence gate's parameters (semantics §15); [`SequenceParams::default`]
    /// unless the file sets them.
    pub sequence_gate: SequenceParams,
}

impl Default for Defaults {
    fn default() -> Self {
        Self {
            k: DEFAULT_K,
            precision: DEFAULT_PRECISION,
            window: None,
            gate: Gate::None,
            sequence_gate: SequenceParams::default(),
        }
    }
}

impl Defaults {
    /// Check `k >= 1`, tau in (0, 1], a window, if any, of at least 1, and the sequence
    /// gate's parameters.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the parameter.
    pub fn validate(&self) -> Result<()> {
        check_k(self.k)?;
        check_precision(self.precision)?;
        self.window.map_or(Ok(()), check_window)?;
        self.sequence_gate.validate()
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
        sequence_gate: SequenceOverrides,
    ) -> Result<Defaults> {
        let defaults = Defaults {
            k: k.unwrap_or(self.k),
            precision: precision.unwrap_or(self.precision),
            window: window.or(self.window),
            gate: gate.unwrap_or(self.gate),
            sequence_gate: self.sequence_gate.overridden(sequence_gate),
        };
        defaults.validate()?;
        Ok(defaults)
    }
}

/// Parameters of a transfer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Params {
    /// Calibration queries sampled per deployment query (clipped to |Qcal|); at least 1.
    pub k: usize,
    /// Precision target tau in (0, 1].
    pub precision: f64,
    /// Deployment queries per segment; `None` is one batch of all of them.
    pub segment_size: Option<usize>,
    /// The gates (semantics §13, §15): with the margin gate the transfer also gives
    /// `m*` and every query's margin, with the sequence gate its level and every
    /// query's consistency.
    pub gate: Gate,
    /// The sequence gate's parameters (semantics §15), read when `gate` has it.
    pub sequence_gate: SequenceParams,
}

/// `k`, `precision`, `segment_size`, `gate`, and `sequence_gate` only when the gate has
/// it (a document of a transfer without the sequence gate shows none of its
/// parameters). Written by hand for that condition, which serde's attributes cannot
/// state (`skip_serializing_if` sees one field).
#[cfg(feature = "serde")]
impl serde::Serialize for Params {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> std::result::Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        let sequence = self.gate.sequence();
        let mut map = serializer.serialize_map(Some(4 + usize::from(sequence)))?;
        map.serialize_entry("k", &self.k)?;
        map.serialize_entry("precision", &self.precision)?;
        map.serialize_entry("segment_size", &self.segment_size)?;
        map.serialize_entry("gate", &self.gate)?;
        if sequence {
            map.serialize_entry("sequence_gate", &self.sequence_gate)?;
        }
        map.end()
    }
}

impl Default for Params {
    fn default() -> Self {
        Self {
            k: DEFAULT_K,
            precision: DEFAULT_PRECISION,
            segment_size: None,
            gate: Gate::None,
            sequence_gate: SequenceParams::default(),
        }
    }
}

impl Params {
    /// Check `k >= 1`, tau in (0, 1] and the sequence gate's parameters (a segment size
    /// is checked against the number of deployment queries by the transfer).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the parameter.
    pub fn validate(&self) -> Result<()> {
        check_k(self.k)?;
        check_precision(self.precision)?;
        self.sequence_gate.validate()
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
        sequence_gate: SequenceOverrides,
    ) -> Result<Params> {
        let params = Params {
            k: k.unwrap_or(defaults.k),
            precision: precision.unwrap_or(defaults.precision),
            segment_size,
            gate: gate.unwrap_or(defaults.gate),
            sequence_gate: defaults.sequence_gate.overridden(sequence_gate),
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
    /// The gates (semantics §13, §15).
    pub gate: Gate,
    /// The sequence gate's parameters (semantics §15), read when `gate` has it.
    pub sequence_gate: SequenceParams,
}

impl OnlineParams {
    /// Check `k >= 1`, precision in (0, 1], `window >= 1`, `1 <= min_window <= window`
    /// and the sequence gate's parameters.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the parameter.
    pub fn validate(&self) -> Result<()> {
        check_k(self.k)?;
        check_precision(self.precision)?;
        self.sequence_gate.validate()?;
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
        sequence_gate: SequenceOverrides,
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
            sequence_gate: defaults.sequence_gate.overridden(sequence_gate),
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

/// The gates a request enables (semantics §13, §15): a set of them, named by the gates
/// it holds joined by commas in a fixed order (`"margin,sequence"`).
///
/// A best match is kept when its score reaches the threshold and every gate of the set
/// passes (the accept rule of `gates/mod.rs`). Parsed from any order of the names
/// (`"sequence,margin"` is `"margin,sequence"`); `"none"` is the empty set.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Gate {
    /// No gate: quantile transfer alone (the paper's method).
    #[default]
    None,
    /// The margin gate (semantics §13): a best match's margin must reach the
    /// calibration's `m*` too.
    Margin,
    /// The sequence gate (semantics §15): a best match's consistency with the previous
    /// queries' must reach its level too.
    Sequence,
    /// Both gates.
    MarginSequence,
}

impl Gate {
    /// Every set, in the order help texts list them.
    pub const ALL: [Gate; 4] = [Gate::None, Gate::Margin, Gate::Sequence, Gate::MarginSequence];

    /// The name of each single gate, in the order a set's name lists them.
    const NAMES: [(&'static str, Gate); 2] = [("margin", Gate::Margin), ("sequence", Gate::Sequence)];

    /// The name used on the command line, in files, in JSON and in Python: `"none"`,
    /// or the gates' names joined by commas (`"margin,sequence"`).
    pub fn as_str(self) -> &'static str {
        match self {
            Gate::None => "none",
            Gate::Margin => "margin",
            Gate::Sequence => "sequence",
            Gate::MarginSequence => "margin,sequence",
        }
    }

    /// The set of the gates asked for.
    pub fn of(margin: bool, sequence: bool) -> Gate {
        match (margin, sequence) {
            (false, false) => Gate::None,
            (true, false) => Gate::Margin,
            (false, true) => Gate::Sequence,
            (true, true) => Gate::MarginSequence,
        }
    }

    /// Whether the set holds the margin gate (semantics §13).
    pub fn margin(self) -> bool {
        matches!(self, Gate::Margin | Gate::MarginSequence)
    }

    /// Whether the set holds the sequence gate (semantics §15).
    pub fn sequence(self) -> bool {
        matches!(self, Gate::Sequence | Gate::MarginSequence)
    }

    /// Whether this set holds every gate of `other`.
    pub fn includes(self, other: Gate) -> bool {
        (self.margin() || !other.margin()) && (self.sequence() || !other.sequence())
    }

    /// The gates of either set.
    #[must_use]
    pub fn union(self, other: Gate) -> Gate {
        Gate::of(self.margin() || other.margin(), self.sequence() || other.sequence())
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
    /// `"none"`, or gate names joined by commas, each once, in any order (spaces around
    /// a name are ignored).
    fn from_str(s: &str) -> Result<Self> {
        let expected = || {
            let names: Vec<&str> = Gate::NAMES.iter().map(|(n, _)| *n).collect();
            format!("none, or one or more of {} joined by commas", names.join(", "))
        };
        if s.trim() == "none" {
            return Ok(Gate::None);
        }
        let mut set = Gate::None;
        for name in s.split(',').map(str::trim) {
            let Some(&(_, gate)) = Gate::NAMES.iter().find(|(n, _)| *n == name) else {
                return Err(Error::param(
                    "gate",
                    format!("must be {}, got {s:?}: unknown gate {name:?}", expected()),
                ));
            };
            if set.includes(gate) {
                return Err(Error::param("gate", format!("names {name} twice in {s:?}")));
            }
            set = set.union(gate);
        }
        Ok(set)
    }
}

#[cfg(feature = "serde")]
impl serde::Serialize for Gate {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> std::result::Result<S::Ok, S::Error> {
        serializer.serialize_str(self.as_str())
    }
}

/// The speed ratio when none is given: both traverses at the same spacing.
pub const DEFAULT_SPEED: f64 = 1.0;
/// The tolerance of one step when none is given, in database rows.
pub const DEFAULT_TOLERANCE: f64 = 2.0;
/// How much the tolerance widens per step away when none is given, in rows per step.
pub const DEFAULT_DRIFT: f64 = 0.2;
/// The sequence gate's window when none is given: the previous 5 queries.
pub const DEFAULT_SEQUENCE_WINDOW: usize = 5;
/// The sequence gate's level when none is given: 4 of the previous 5 queries agree.
pub const DEFAULT_SEQUENCE_LEVEL: f64 = 0.8;

/// The line a query's best match draws through the database, and how near another
/// query's best match must lie to agree with it (semantics §15; the agreement itself is
/// `rules/agreement.rs`').
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct Line {
    /// `v`: database rows per query (1: the same spacing; -1: the route driven backwards).
    pub speed: f64,
    /// `a >= 0`: how far from the prediction a neighbour one step away may lie, in rows.
    pub tolerance: f64,
    /// `b >= 0`: how much that widens per step away, in rows per step.
    pub drift: f64,
}

impl Default for Line {
    fn default() -> Self {
        Self::DEFAULT
    }
}

impl Line {
    /// [`Line::default`], in a `const`.
    pub const DEFAULT: Line = Line {
        speed: DEFAULT_SPEED,
        tolerance: DEFAULT_TOLERANCE,
        drift: DEFAULT_DRIFT,
    };

    /// Check that the speed is finite and the tolerance and drift finite and `>= 0`.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the parameter (`sequence speed`, `sequence
    /// tolerance` or `sequence drift`).
    pub fn validate(&self) -> Result<()> {
        if !self.speed.is_finite() {
            return Err(Error::param(
                "sequence speed",
                format!("must be finite, got {}", self.speed),
            ));
        }
        for (name, value) in [("sequence tolerance", self.tolerance), ("sequence drift", self.drift)] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(Error::param(name, format!("must be finite and >= 0, got {value}")));
            }
        }
        Ok(())
    }
}

/// The parameters of the sequence gate (semantics §15): how many previous queries a
/// query is compared with, the consistency it needs, and the line of the agreement.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct SequenceParams {
    /// `W >= 1`: how many previous queries a query is compared with.
    pub window: usize,
    /// In (0, 1]: the consistency a query needs to pass.
    pub level: f64,
    /// The line a best match draws and how near its neighbours must lie
    /// (`speed`, `tolerance`, `drift`).
    #[cfg_attr(feature = "serde", serde(flatten))]
    pub line: Line,
}

impl Default for SequenceParams {
    fn default() -> Self {
        Self::DEFAULT
    }
}

impl SequenceParams {
    /// [`SequenceParams::default`], in a `const`.
    pub const DEFAULT: SequenceParams = SequenceParams {
        window: DEFAULT_SEQUENCE_WINDOW,
        level: DEFAULT_SEQUENCE_LEVEL,
        line: Line::DEFAULT,
    };

    /// Check the window (>= 1), the level (in (0, 1]) and the line
    /// ([`Line::validate`]).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the parameter (`sequence window`, `sequence
    /// level`, ...).
    pub fn validate(&self) -> Result<()> {
        if self.window < 1 {
            return Err(Error::param(
                "sequence window",
                format!("must be >= 1, got {}", self.window),
            ));
        }
        if !(self.level > 0.0 && self.level <= 1.0) {
            return Err(Error::param(
                "sequence level",
                format!("must be in (0, 1], got {}", self.level),
            ));
        }
        self.line.validate()
    }

    /// These parameters with each one `given` replacing its own (unchecked: the request
    /// that holds them is validated).
    #[must_use]
    pub fn overridden(&self, given: SequenceOverrides) -> SequenceParams {
        SequenceParams {
            window: given.window.unwrap_or(self.window),
            level: given.level.unwrap_or(self.level),
            line: Line {
                speed: given.speed.unwrap_or(self.line.speed),
                tolerance: given.tolerance.unwrap_or(self.line.tolerance),
                drift: given.drift.unwrap_or(self.line.drift),
            },
        }
    }
}

/// The sequence gate's parameters a user gave (`--sequence-window`, `sequence_window=`,
/// ...), each `None` when left out: the calibration's (its file's `params`), else the
/// defaults. [`Default`] is none given.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SequenceOverrides {
    /// The window `W`.
    pub window: Option<usize>,
    /// The level.
    pub level: Option<f64>,
    /// The speed ratio `v`.
    pub speed: Option<f64>,
    /// The tolerance `a`.
    pub tolerance: Option<f64>,
    /// The drift `b`.
    pub drift: Option<f64>,
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
            sequence_gate: SequenceParams::default(),
        };
        let p = Params::resolve(&file, None, None, Some(5), None, SequenceOverrides::default()).unwrap();
        assert_eq!((p.k, p.precision, p.segment_size), (3, 0.9, Some(5)));
        let p = Params::resolve(&file, Some(7), Some(1.0), None, None, SequenceOverrides::default()).unwrap();
        assert_eq!((p.k, p.precision, p.segment_size), (7, 1.0, None));
        let o = OnlineParams::resolve(&file, None, None, None, None, None, SequenceOverrides::default()).unwrap();
        assert_eq!((o.k, o.precision, o.window, o.min_window), (3, 0.9, 28, 1));
        let o = OnlineParams::resolve(
            &file,
            Some(1),
            Some(0.5),
            Some(4),
            Some(4),
            None,
            SequenceOverrides::default(),
        )
        .unwrap();
        assert_eq!((o.k, o.precision, o.window, o.min_window), (1, 0.5, 4, 4));
        assert_eq!(
            file.resolve(None, None, None, None, SequenceOverrides::default())
                .unwrap(),
            file
        );
        assert_eq!(
            file.resolve(Some(4), None, Some(2), None, SequenceOverrides::default())
                .unwrap()
                .window,
            Some(2)
        );
        // No file: the library's.
        let p = Params::resolve(
            &Defaults::default(),
            None,
            None,
            None,
            None,
            SequenceOverrides::default(),
        )
        .unwrap();
        assert_eq!(p, Params::default());
    }

    #[test]
    fn one_set_of_checks_and_messages() {
        let d = Defaults::default();
        let err = |r: Result<Params>| r.unwrap_err().to_string();
        assert_eq!(
            err(Params::resolve(
                &d,
                Some(0),
                None,
                None,
                None,
                SequenceOverrides::default()
            )),
            "k must be >= 1, got 0"
        );
        assert_eq!(
            err(Params::resolve(
                &d,
                None,
                Some(1.5),
                None,
                None,
                SequenceOverrides::default()
            )),
            "precision must be in (0, 1], got 1.5"
        );
        let online = |w, m| {
            OnlineParams::resolve(&d, None, None, w, m, None, SequenceOverrides::default())
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
            d.resolve(Some(0), None, None, None, SequenceOverrides::default())
                .unwrap_err()
                .to_string(),
            "k must be >= 1, got 0"
        );
        assert_eq!(
            d.resolve(None, None, Some(0), None, SequenceOverrides::default())
                .unwrap_err()
                .to_string(),
            "window must be >= 1, got 0"
        );
    }

    #[test]
    fn a_gate_set_is_named_by_its_gates_in_any_order() {
        assert_eq!("none".parse::<Gate>().unwrap(), Gate::None);
        assert_eq!("margin".parse::<Gate>().unwrap(), Gate::Margin);
        assert_eq!("sequence".parse::<Gate>().unwrap(), Gate::Sequence);
        // Either order, written back in one.
        for name in ["margin,sequence", "sequence,margin", " sequence , margin "] {
            let gate: Gate = name.parse().unwrap();
            assert_eq!(gate, Gate::MarginSequence);
            assert_eq!(gate.as_str(), "margin,sequence");
        }
        assert!(Gate::MarginSequence.includes(Gate::Sequence) && !Gate::Margin.includes(Gate::Sequence));
        assert!(Gate::Sequence.includes(Gate::None) && Gate::None.includes(Gate::None));
        assert_eq!(Gate::Margin.union(Gate::Sequence), Gate::MarginSequence);
        assert_eq!((Gate::Sequence.margin(), Gate::Sequence.sequence()), (false, true));
        let err = |s: &str| s.parse::<Gate>().unwrap_err().to_string();
        assert_eq!(
            err("ratio"),
            "gate must be none, or one or more of margin, sequence joined by commas, got \"ratio\": \
             unknown gate \"ratio\""
        );
        assert_eq!(
            err("margin,none"),
            "gate must be none, or one or more of margin, sequence joined by commas, got \"margin,none\": \
             unknown gate \"none\""
        );
        assert_eq!(err("margin,margin"), "gate names margin twice in \"margin,margin\"");
        assert_eq!(
            err("sequence,margin,sequence"),
            "gate names sequence twice in \"sequence,margin,sequence\""
        );
        assert!(err("").ends_with("unknown gate \"\""));
    }

    #[test]
    fn the_sequence_gate_takes_each_parameter_given_and_the_files_for_the_others() {
        let file = Defaults {
            gate: Gate::Sequence,
            sequence_gate: SequenceParams {
                window: 7,
                level: 0.6,
                line: Line {
                    speed: -1.0,
                    ..Line::default()
                },
            },
            ..Defaults::default()
        };
        let given = SequenceOverrides {
            level: Some(1.0),
            drift: Some(0.0),
            ..SequenceOverrides::default()
        };
        let want = SequenceParams {
            window: 7,
            level: 1.0,
            line: Line {
                speed: -1.0,
                tolerance: DEFAULT_TOLERANCE,
                drift: 0.0,
            },
        };
        let p = Params::resolve(&file, None, None, None, None, given).unwrap();
        assert_eq!((p.gate, p.sequence_gate), (Gate::Sequence, want));
        let o = OnlineParams::resolve(&file, None, None, Some(3), None, Some(Gate::None), given).unwrap();
        assert_eq!((o.gate, o.sequence_gate), (Gate::None, want));
        assert_eq!(file.resolve(None, None, None, None, given).unwrap().sequence_gate, want);
        // Checked whether or not the gate is on, naming the parameter.
        let bad = SequenceOverrides {
            window: Some(0),
            ..SequenceOverrides::default()
        };
        assert_eq!(
            Params::resolve(&Defaults::default(), None, None, None, None, bad)
                .unwrap_err()
                .to_string(),
            "sequence window must be >= 1, got 0"
        );
        let bad = SequenceOverrides {
            tolerance: Some(-1.0),
            ..SequenceOverrides::default()
        };
        assert_eq!(
            OnlineParams::resolve(&file, None, None, Some(3), None, None, bad)
                .unwrap_err()
                .to_string(),
            "sequence tolerance must be finite and >= 0, got -1"
        );
    }
}
