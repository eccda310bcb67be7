//! semantics §12: the calibration file, so that calibration is done once, offline, and
//! a deployed system loads it.
//!
//! A NumPy `.npz` archive (uncompressed, no pickle: `np.load` reads it) of:
//!
//! | array | dtype, shape | holds |
//! |---|---|---|
//! | `s` | float32 or float64 (the input's own), \|DB\| x \|Qcal\| | the calibration similarity, DB x Q whatever the input's orientation |
//! | `gt` | bool, the same shape | the hard ground truth |
//! | `gt_soft` | bool, the same shape | the soft ground truth (hard or soft); only when some entry is soft but not hard |
//! | `meta` | `<U{n}`, shape `()` | JSON, below |
//!
//! ```json
//! {"format": "qtvpr-calibration", "version": 1, "matching": "single",
//!  "params": {"k": 10, "precision": 1.0, "window": 28, "gate": "none"}, "qtvpr": "0.1.0"}
//! ```
//!
//! `params` are [`Defaults`](crate::input::params::Defaults) for whoever uses the file (`window` is `null` when none is
//! set; `gate`, `"none"`, `"margin"`, `"sequence"` or `"margin,sequence"`, is `"none"`
//! when left out; `sequence_gate`, the sequence gate's `window`, `level`, `speed`,
//! `tolerance` and `drift`, is written in full when the gate is on or a parameter is
//! not its default, and each key left out is its default); each can be overridden
//! there. `sequence` is the calibration's sequence length `L` (semantics §15: not a
//! default but what `s` was matched over), written when it is above 1 and 1 when left
//! out. `qtvpr` is the version of the crate that wrote it. `labels`, only when the
//! ground truth came from self-motion labels (semantics §16), is their record
//! ([`LabelRecord`](crate::input::LabelRecord)), checked on load; such a calibration is
//! single matching. Keys beyond these are ignored on load.
//!
//! Loading checks everything the same arrays are checked for as input (finite, non-empty
//! scores; bool ground truth of the same shape), the `format` and `version`, the
//! `matching` and `params`; every error names the file. A loaded calibration is built
//! from the same scores and labels as the one saved, so its results are bit-identical.

/// The `format` of a calibration file's `meta`.
pub const FORMAT: &str = "qtvpr-calibration";

/// The calibration file version this crate writes and reads.
pub const VERSION: u64 = 1;

#[cfg(feature = "npy")]
mod file {
    use std::path::Path;

    use ndarray::Array2;
    use serde::{Deserialize, Serialize};

    use super::{FORMAT, VERSION};
    use crate::error::names::Input;
    use crate::error::{Error, Result};
    use crate::extensions::sequence::Sequence;
    use crate::files::npy::{self, NpyArray};
    use crate::input::params::{Defaults, Gate, Line, SequenceParams};
    use crate::input::{GroundTruth, LabelRecord, ScoreMatrix, Truth};
    use crate::operations::calibration::Calibration;
    use crate::rules::decisions::Matching;
    use crate::signals::self_motion::check_record;

    /// The `meta` JSON.
    #[derive(Serialize, Deserialize)]
    struct Meta {
        format: String,
        version: u64,
        matching: String,
        params: Params,
        /// The version of qtvpr that wrote the file: informative only, so a file written
        /// by another tool may leave it out.
        #[serde(default)]
        qtvpr: String,
        /// The record of self-motion labels (semantics §16), when the ground truth is
        /// theirs.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        labels: Option<serde_json::Value>,
    }

    #[derive(Serialize, Deserialize)]
    struct Params {
        k: usize,
        precision: f64,
        window: Option<usize>,
        /// Left out by files written before the gate: none.
        #[serde(default)]
        gate: Option<String>,
        /// The sequence gate's parameters (semantics §15): left out when the gate is off
        /// and they are the defaults, and by files written before the gate.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        sequence_gate: Option<SequenceGate>,
        /// The calibration's sequence length `L` (semantics §15): left out for 1.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        sequence: Option<usize>,
    }

    /// `params.sequence_gate`: each key left out takes its default.
    #[derive(Serialize, Deserialize)]
    struct SequenceGate {
        window: Option<usize>,
        level: Option<f64>,
        speed: Option<f64>,
        tolerance: Option<f64>,
        drift: Option<f64>,
    }

    impl From<SequenceParams> for SequenceGate {
        fn from(p: SequenceParams) -> Self {
            Self {
                window: Some(p.window),
                level: Some(p.level),
                speed: Some(p.line.speed),
                tolerance: Some(p.line.tolerance),
                drift: Some(p.line.drift),
            }
        }
    }

    impl From<SequenceGate> for SequenceParams {
        fn from(g: SequenceGate) -> Self {
            let d = SequenceParams::default();
            SequenceParams {
                window: g.window.unwrap_or(d.window),
                level: g.level.unwrap_or(d.level),
                line: Line {
                    speed: g.speed.unwrap_or(d.line.speed),
                    tolerance: g.tolerance.unwrap_or(d.line.tolerance),
                    drift: g.drift.unwrap_or(d.line.drift),
                },
            }
        }
    }

    fn file_error(path: &Path, message: impl Into<String>) -> Error {
        Error::File {
            path: path.display().to_string(),
            message: message.into(),
        }
    }

    fn in_file(path: &Path, e: Error) -> Error {
        Error::InFile {
            path: path.display().to_string(),
            error: Box::new(e),
        }
    }

    impl Calibration {
        /// Write this calibration as a calibration file (an `.npz`; see
        /// semantics §12) with `defaults` as its `params`, atomically
        /// (temporary file and rename; the file gets the mode a plain create gives).
        ///
        /// # Errors
        /// [`Error::InvalidParameter`] for bad `defaults` or a calibration that did not keep
        /// its input ([`Calibration::for_transfer`]); [`Error::Write`] naming `path`.
        pub fn save(&self, path: &Path, defaults: &Defaults) -> Result<()> {
            let (meta, gt, soft) = self.file_arrays(defaults)?;
            npy::write_npz(path, &self.members(&meta, &gt, soft.as_ref()))
        }

        /// The calibration file as bytes (for sending it elsewhere, e.g. pickling).
        ///
        /// # Errors
        /// As [`Calibration::save`], but for writing.
        pub fn to_bytes(&self, defaults: &Defaults) -> Result<Vec<u8>> {
            let (meta, gt, soft) = self.file_arrays(defaults)?;
            let mut out = Vec::new();
            npy::write_npz_to(&mut out, &self.members(&meta, &gt, soft.as_ref())).map_err(|e| Error::Write {
                path: "memory".into(),
                kind: e.kind(),
                message: e.to_string(),
            })?;
            Ok(out)
        }

        /// Load a calibration file written by [`Calibration::save`]; its `params` become
        /// [`Calibration::defaults`].
        ///
        /// # Errors
        /// [`Error::Io`] if the file cannot be read; [`Error::File`], [`Error::Dtype`] or
        /// [`Error::InFile`] naming it for anything wrong inside (not an `.npz`, a missing
        /// or malformed array, shapes that disagree, a non-finite score, non-bool ground
        /// truth, an unknown format or version, bad `meta`).
        pub fn load(path: &Path) -> Result<Calibration> {
            npy::guarded(path, || read(npy::open_npz_file(path)?, path))
        }

        /// [`Calibration::load`] from the bytes of a calibration file; `name` stands for
        /// the file in errors.
        ///
        /// # Errors
        /// As [`Calibration::load`].
        pub fn from_bytes(bytes: &[u8], name: &str) -> Result<Calibration> {
            let path = Path::new(name);
            npy::guarded(path, || read(npy::Archive::new(bytes, bytes.len() as u64, path)?, path))
        }

        /// The `meta` JSON and the hard and (if any entry is ignored) soft ground truth,
        /// once `defaults` are checked and the calibration is known to keep its input.
        fn file_arrays(&self, defaults: &Defaults) -> Result<(String, Array2<bool>, Option<Array2<bool>>)> {
            self.check_defaults(defaults)?;
            let labels = self.ground_truth().ok_or_else(|| {
                Error::param(
                    "calibration",
                    "was built by Calibration::for_transfer, which keeps neither its scores nor its \
                     ground truth, so it cannot be saved: build it with Calibration::new",
                )
            })?;
            let meta = Meta {
                format: FORMAT.into(),
                version: VERSION,
                matching: self.matching().as_str().into(),
                params: Params {
                    k: defaults.k,
                    precision: defaults.precision,
                    window: defaults.window,
                    gate: Some(defaults.gate.as_str().into()),
                    sequence_gate: (defaults.gate.sequence() || defaults.sequence_gate != SequenceParams::default())
                        .then(|| defaults.sequence_gate.into()),
                    sequence: (self.sequence() > 1).then_some(self.sequence()),
                },
                qtvpr: env!("CARGO_PKG_VERSION").into(),
                labels: self
                    .labels()
                    .map(|r| serde_json::from_str(r.json()).expect("a record is checked JSON")),
            };
            let meta = serde_json::to_string(&meta).expect("meta serialises");
            let labels = labels.view();
            let gt = labels.mapv(|t| t == Truth::True);
            let soft = labels
                .iter()
                .any(|&t| t == Truth::Ignored)
                .then(|| labels.mapv(|t| t != Truth::False));
            Ok((meta, gt, soft))
        }

        fn members<'a>(
            &'a self,
            meta: &'a str,
            gt: &'a Array2<bool>,
            soft: Option<&'a Array2<bool>>,
        ) -> Vec<(&'static str, NpyArray<'a>)> {
            let s = match self.scores().expect("file_arrays checked that the input is kept") {
                ScoreMatrix::F32(m) => NpyArray::F32(m.view()),
                ScoreMatrix::F64(m) => NpyArray::F64(m.view()),
            };
            let mut members = vec![("s", s), ("gt", NpyArray::Bool(gt.view()))];
            if let Some(soft) = soft {
                members.push(("gt_soft", NpyArray::Bool(soft.view())));
            }
            members.push(("meta", NpyArray::Str(meta)));
            members
        }
    }

    /// A calibration from an opened archive; `path` names it in errors.
    ///
    /// Integrity first: the archive's every member was checked when it was opened
    /// (methods, flags, extra fields, local headers: `npy/archive.rs`); here every
    /// array's `.npy` header is read (dtype, rank, the size the zip directory declares)
    /// and the shapes compared before any array data is decompressed; each array is then
    /// read to its end, so that its CRC-32 is checked, and never past its declared size;
    /// and so is any other member the archive holds.
    fn read<R: rawzip::ReaderAt>(npz: npy::Archive<R>, path: &Path) -> Result<Calibration> {
        use npy::Kind;
        let missing = |name: &str| {
            file_error(
                path,
                format!("has no array {name}; a calibration file holds s, gt and meta (and optionally gt_soft)"),
            )
        };
        let meta = npy::npz_array(&npz, "meta", Kind::Text)?
            .ok_or_else(|| file_error(path, "has no array meta: it is not a qtvpr calibration file"))?;
        let s = npy::npz_array(&npz, "s", Kind::Scores)?.ok_or_else(|| missing("s"))?;
        let hard = npy::npz_array(&npz, "gt", Kind::Bool)?.ok_or_else(|| missing("gt"))?;
        let soft = npy::npz_array(&npz, "gt_soft", Kind::Bool)?;
        // The shapes agree before any array is decompressed (the same messages as the
        // checks on the arrays themselves).
        let pairs = [
            (Some(&hard), &s, Input::GroundTruth, Input::CalSimilarity),
            (soft.as_ref(), &hard, Input::SoftGroundTruth, Input::GroundTruth),
        ];
        for (member, other, what, other_what) in pairs {
            if let Some(member) = member
                && member.dims() != other.dims()
            {
                return Err(in_file(
                    path,
                    Error::ShapeMismatch {
                        what,
                        shape: member.dims(),
                        other: other_what,
                        other_shape: other.dims(),
                    },
                ));
            }
        }
        let (matching, defaults, sequence, record) = read_meta(&npy::read_string(meta.npy, &meta.label)?, path)?;
        let scores = npy::read_owned_scores(s.npy, &s.label)?;
        let hard_gt = npy::read_bool_matrix(hard.npy, &hard.label)?;
        let mut gt = GroundTruth::new(hard_gt.view())
            .map_err(|e| in_file(path, e))?
            .with_record(record);
        if let Some(soft) = soft {
            let soft_gt = npy::read_bool_matrix(soft.npy, &soft.label)?;
            gt = gt.with_soft(soft_gt.view()).map_err(|e| in_file(path, e))?;
        }
        npz.check_unread_members()?;
        let calibration =
            with_scores!(scores.view(), |m| Calibration::new(m, &gt, matching)).map_err(|e| in_file(path, e))?;
        // `s` is already matched over the file's sequence length.
        calibration
            .with_sequence(sequence)
            .with_defaults(defaults)
            .map_err(|e| in_file(path, e))
    }

    /// The matching mode, defaults, sequence length and record of self-motion labels of a
    /// `meta` JSON text.
    fn read_meta(text: &str, path: &Path) -> Result<(Matching, Defaults, usize, Option<LabelRecord>)> {
        let bad = |message: String| file_error(path, message);
        let value: serde_json::Value =
            serde_json::from_str(text).map_err(|e| bad(format!("has a meta that is not JSON: {e}")))?;
        match value.get("format").and_then(|f| f.as_str()) {
            Some(FORMAT) => {}
            Some(other) => {
                return Err(bad(format!(
                    "is not a qtvpr calibration file: its meta format is '{other}', expected '{FORMAT}'"
                )));
            }
            None => return Err(bad(format!("has a meta without a format string; expected '{FORMAT}'"))),
        }
        match value.get("version") {
            Some(v) if v.as_u64() == Some(VERSION) => {}
            Some(v) => {
                return Err(bad(format!(
                    "has calibration file version {v}; this qtvpr ({}) reads version {VERSION}",
                    env!("CARGO_PKG_VERSION")
                )));
            }
            None => return Err(bad("has a meta without a version".into())),
        }
        let meta: Meta = serde_json::from_value(value).map_err(|e| bad(format!("has a malformed meta: {e}")))?;
        let matching = meta.matching.parse().map_err(|_| {
            bad(format!(
                "has meta matching '{}'; expected 'single' or 'multi'",
                meta.matching
            ))
        })?;
        let bad_params = |e: Error| bad(format!("has bad meta params: {e}"));
        let defaults = Defaults {
            k: meta.params.k,
            precision: meta.params.precision,
            window: meta.params.window,
            gate: meta
                .params
                .gate
                .as_deref()
                .map_or(Ok(Gate::None), str::parse)
                .map_err(bad_params)?,
            sequence_gate: meta.params.sequence_gate.map(SequenceParams::from).unwrap_or_default(),
        };
        defaults.validate().map_err(bad_params)?;
        let sequence = meta.params.sequence.unwrap_or(1);
        Sequence::causal(sequence).validate().map_err(bad_params)?;
        let record = meta
            .labels
            .map(|labels| {
                check_record(labels).map_err(|why| {
                    bad(format!(
                        "has meta labels that are not a record of self-motion labels: it {why}"
                    ))
                })
            })
            .transpose()?;
        Ok((matching, defaults, sequence, record))
    }
}
