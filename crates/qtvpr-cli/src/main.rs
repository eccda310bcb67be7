//! `qtvpr-cli`: thresholds for visual place recognition by quantile transfer.
//!
//! A thin front end: argument parsing, `.npy`/`.npz` reading and output formatting.
//! All the arithmetic lives in the `qtvpr` crate.

use std::io;
use std::process::ExitCode;

use anyhow::Context;
use clap::{Parser, Subcommand};

mod args;
mod calibrate;
mod embedded;
mod evaluate;
mod ground_truth;
mod gt_source;
mod output;
mod plot;
mod progress;
mod similarity;
mod stream;
mod summary;
mod threshold;

/// Choose the operating point of a visual place recognition system by quantile
/// transfer (Rajani, Milford, Fischer, IROS 2026).
///
/// Similarity matrices are |DB| x |Q| (one column per query, higher = more similar)
/// unless --query-major is given. Errors exit with status 2.
#[derive(Debug, Parser)]
#[command(name = "qtvpr-cli", version, about, long_about)]
struct Cli {
    #[command(flatten)]
    global: Global,
    #[command(subcommand)]
    command: Command,
}

/// The help heading of [`Global`]'s options.
const GLOBAL_HEADING: &str = "Global options";

/// Options of every command, listed under their own heading at the end of each
/// command's help (after the command's own options, which are what a reader looks for).
#[derive(Debug, clap::Args)]
#[command(next_help_heading = GLOBAL_HEADING)]
pub struct Global {
    /// Worker threads, at most 1024 (default: RAYON_NUM_THREADS if set, else all cores).
    #[arg(long, global = true, value_name = "N")]
    threads: Option<usize>,
    /// No progress bar (it is shown only when stderr is a terminal anyway).
    #[arg(long, short, global = true)]
    pub quiet: bool,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Calibrate on a traverse with ground truth; print one threshold per segment of
    /// deployment queries (no deployment ground truth needed).
    Threshold(threshold::ThresholdArgs),
    /// Check a calibration traverse with ground truth and write it as one calibration
    /// file (.npz), once, offline, for `stream`, `threshold` and a deployed system to load.
    Calibrate(calibrate::CalibrateArgs),
    /// Replay a deployment matrix query by query, as a robot sees it: each query is
    /// thresholded on its last --window queries (a causal window) and decided at once;
    /// one line per query.
    Stream(stream::StreamArgs),
    /// Run the paper's evaluation protocol on a matrix with ground truth for every
    /// query: the first queries calibrate, the rest are cut into segments, and each
    /// method's per-segment threshold is scored against the segment's ground truth
    /// (%Segs: segments that stay at the target precision; AvgR: their mean recall).
    /// Without --similarity, runs on the embedded demo data and prints a table.
    Evaluate(evaluate::EvaluateArgs),
    /// Similarity matrix from descriptor files (cosine of L2-normalised rows), optionally
    /// sequence-matched; writes |DB| x |Q| float32 .npy.
    Similarity(similarity::SimilarityArgs),
    /// Ground-truth matrix from a frame tolerance or from positions, or for calibration
    /// queries without any, from their order on the traverse (--from-sequence); writes
    /// bool .npy or a VPR_Tutorial .npz.
    GroundTruth(ground_truth::GroundTruthArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = configure_threads(cli.global.threads).and_then(|()| match &cli.command {
        Command::Threshold(args) => threshold::run(args, &cli.global),
        Command::Calibrate(args) => calibrate::run(args),
        Command::Stream(args) => stream::run(args, &cli.global),
        Command::Evaluate(args) => evaluate::run(args, &cli.global),
        Command::Similarity(args) => similarity::run(args, &cli.global),
        Command::GroundTruth(args) => ground_truth::run(args),
    });
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) if is_broken_pipe(&err) => ExitCode::SUCCESS,
        Err(err) => {
            // One line, whatever the underlying error printed.
            let msg = format!("{err:#}");
            eprintln!("error: {}", msg.lines().map(str::trim).collect::<Vec<_>>().join(" "));
            ExitCode::from(2)
        }
    }
}

/// Size the library's own pool (qtvpr::set_threads), not rayon's global one: the core runs
/// every parallel region there, so that a forked child gets live threads. The core
/// refuses 0 and more than qtvpr::MAX_THREADS.
fn configure_threads(threads: Option<usize>) -> anyhow::Result<()> {
    threads.map_or(Ok(()), |n| qtvpr::set_threads(n).context("--threads"))
}

fn is_broken_pipe(err: &anyhow::Error) -> bool {
    err.chain().any(|e| {
        e.downcast_ref::<io::Error>()
            .is_some_and(|e| e.kind() == io::ErrorKind::BrokenPipe)
    })
}
