//! `qtvpr-cli stream`: replay a deployment matrix query by query through
//! [`qtvpr::Online`], as a robot would see it, and write one line per query: its
//! threshold and decision. A calibration file of sequence length `L > 1` (semantics
//! §15) decides each query on its causal sequence-matched column.

use std::io::{self, BufWriter, Write};
use std::path::PathBuf;
use std::sync::Arc;

use anyhow::{Context, Result};
use clap::Args;
use ndarray::ArrayView2;
use qtvpr::{Calibration, Decision, Input, Online, OnlineParams, Score};

use crate::args::{SequenceGateArgs, SplitArgs, gate_parser};
use crate::output::{self, emit};
use crate::{Global, progress};
use qtvpr::npy::{MatrixFile, read_scores};
use qtvpr::with_scores;

/// Arguments of `stream`.
#[derive(Debug, Args)]
pub struct StreamArgs {
    /// Calibration file (.npz) written by `calibrate`.
    #[arg(long, value_name = "cal.npz")]
    calibration: PathBuf,
    /// Deployment similarity matrix (.npy), |DB| x |Qval|, its columns in arrival order.
    #[arg(long, value_name = "S_val.npy")]
    val: PathBuf,
    /// A --val that is the whole recorded traverse the calibration was made on
    /// (`calibrate --similarity` with the same split): its calibration queries are
    /// skipped, and the first line is the first query after them (`query` 0).
    #[command(flatten)]
    split: SplitArgs,
    /// Calibration queries sampled per deployment query [default: the file's].
    #[arg(long)]
    k: Option<usize>,
    /// Target precision tau, in (0, 1] [default: the file's].
    #[arg(long, allow_negative_numbers = true)]
    precision: Option<f64>,
    /// Window: each query is thresholded on its last M queries, itself included
    /// [default: the file's; required if it sets none].
    #[arg(long, value_name = "M")]
    window: Option<usize>,
    /// Warm-up: queries before the W-th are rejected outright (threshold above every
    /// score), so that no decision rests on fewer than W queries.
    #[arg(long, value_name = "W", default_value_t = qtvpr::DEFAULT_MIN_WINDOW)]
    min_window: usize,
    /// `margin`: accept a best match only if its margin (how far it stands out of its
    /// column) is at least the calibration's m* too; each line then also carries
    /// `margin` and `gate` (semantics §13). `sequence`: only if the best matches of the
    /// previous queries agree with it (semantics §15); each line then also carries
    /// `consistency` and `consistency_level`. `margin,sequence`: both. Single matching
    /// only [default: the file's, else none].
    #[arg(long, value_parser = gate_parser())]
    gate: Option<qtvpr::Gate>,
    #[command(flatten)]
    sequence_gate: SequenceGateArgs,
    /// The sequence length L of the calibration file (semantics §15): each query is
    /// decided on its causal sequence-matched column, as `similarity --sequence L
    /// --causal` would match --val. It is the file's (`calibrate --sequence L`); another
    /// one is an error [default: the file's].
    #[arg(long, value_name = "L")]
    sequence: Option<usize>,
    /// --val is stored query-major, |Qval| x |DB| (the VPR-Bench convention).
    #[arg(long)]
    query_major: bool,
    /// Output format: one JSON object per line, or CSV with a header.
    #[arg(long, value_enum, default_value_t = StreamFormat::Jsonl)]
    format: StreamFormat,
    /// Write to this file (atomically, once every query is decided) instead of stdout.
    #[arg(long, short, value_name = "FILE")]
    output: Option<PathBuf>,
}

/// Output formats of `stream`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum StreamFormat {
    /// JSON lines: one object per query.
    Jsonl,
    /// CSV: a header, then one row per query.
    Csv,
}

/// Write one decision as a line of `format`: the core's record, as it serialises, or
/// its values in the order of its fields ([`Decision::values`], the columns of
/// [`Decision::fields`]).
fn write_line(d: &Decision, format: StreamFormat, out: &mut impl Write) -> io::Result<()> {
    match format {
        // Into io::Error, which keeps the write's own error (a closed pipe) for main to
        // find: serde_json's error does not expose it as a source.
        StreamFormat::Jsonl => serde_json::to_writer(&mut *out, d).map_err(io::Error::from)?,
        StreamFormat::Csv => {
            for (i, (_, value)) in d.values().enumerate() {
                write!(out, "{}{value}", if i == 0 { "" } else { "," })?;
            }
        }
    }
    writeln!(out)
}

/// Queries decided per step of the progress bar.
const STEP: usize = 256;

/// Run `stream`.
pub fn run(args: &StreamArgs, global: &Global) -> Result<()> {
    let split = args.split.split()?;
    let cal = Calibration::load(&args.calibration).context("--calibration")?;
    cal.check_sequence(args.sequence)
        .with_context(|| format!("--sequence: --calibration {}", args.calibration.display()))?;
    let calibration_queries = cal.len();
    let params = OnlineParams::resolve(
        cal.defaults(),
        args.k,
        args.precision,
        args.window,
        Some(args.min_window),
        args.gate,
        args.sequence_gate.overrides(),
    )?;
    let mut online = Online::new(Arc::new(cal), params)?;
    let file = read_scores(&args.val).context("--val")?;
    let s_val = file.view().oriented(args.query_major);
    let input = format!("--val {}", args.val.display());
    qtvpr::check_nonempty(Input::DeploymentSimilarity, s_val.dim()).context(input.clone())?;
    // Only the queries after the calibration queries are decided (every query without
    // a split).
    let split = split
        .map(|asked| {
            let split = crate::args::query_split(asked, s_val.dim(), args.query_major, &input)?;
            split
                .check_calibration(calibration_queries)
                .with_context(|| format!("{} of {input} / --calibration {}", asked.1, args.calibration.display()))?;
            anyhow::Ok(split)
        })
        .transpose()?;
    let decided = split.as_ref().map_or(0..s_val.dim().1, qtvpr::QuerySplit::deployment);

    // Lines go to stdout as queries are decided, or to memory for an atomic --output.
    let mut buffer = Vec::new();
    let mut out: Box<dyn Write> = match &args.output {
        None => Box::new(BufWriter::new(output::stdout()?)),
        Some(_) => Box::new(&mut buffer),
    };
    let n_val = decided.len();
    let bar = progress::bar(global.quiet, n_val, "deployment queries");
    let replayed = (|| {
        if args.format == StreamFormat::Csv {
            let header = Decision::fields(online.params().gate).join(",");
            writeln!(out, "{header}").map_err(Failure::Output)?;
        }
        let progress = |done| bar.set_position(done as u64);
        with_scores!(s_val, |v| replay(
            &mut online,
            v.slice_move(ndarray::s![.., decided.clone()]),
            &file,
            args.format,
            &mut out,
            progress
        ))?;
        out.flush().map_err(Failure::Output)
    })();
    bar.finish_and_clear();
    drop(out);
    match replayed {
        // Memory does not fail to write: an output error is standard output's.
        Err(Failure::Output(e)) => return Err(anyhow::Error::new(e).context(output::STDOUT)),
        Err(Failure::Input(e)) => {
            // A position among the decided columns, in the whole matrix's.
            let e = match &split {
                Some(split) => split.deployment_error(e),
                None => e,
            };
            return Err(anyhow::Error::new(e.oriented(args.query_major))).context(input);
        }
        Ok(()) => {}
    }
    match &args.output {
        None => Ok(()),
        Some(path) => emit(std::str::from_utf8(&buffer).expect("the lines are UTF-8"), Some(path)),
    }
}

/// Why a replay stopped: a column the library refused, or an output that could not be
/// written (named differently: the input is not to blame for a closed pipe).
enum Failure {
    Input(qtvpr::Error),
    Output(io::Error),
}

/// Push the columns of `s` one by one, as a robot would, writing each decision as it is
/// made (so that a bad column stops the stream after every query before it). `file`,
/// which `s` views, is checked before each column: a mapped file shrunk meanwhile is
/// an error, not a bus error (a stat per query, against a push of milliseconds).
fn replay<T: Score>(
    online: &mut Online,
    s: ArrayView2<'_, T>,
    file: &MatrixFile,
    format: StreamFormat,
    out: &mut impl Write,
    progress: impl Fn(usize),
) -> Result<(), Failure> {
    for (j, column) in s.columns().into_iter().enumerate() {
        file.check_mapped_file().map_err(Failure::Input)?;
        let decision = online.push(column).map_err(Failure::Input)?;
        write_line(&decision, format, out).map_err(Failure::Output)?;
        if (j + 1) % STEP == 0 || j + 1 == s.ncols() {
            progress(j + 1);
        }
    }
    Ok(())
}
