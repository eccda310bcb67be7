//! `qtvpr-cli evaluate`: the paper's evaluation protocol (semantics §7-§8) on one
//! similarity matrix with ground truth, as JSON, a Markdown table or CSV, with figures.
//!
//! Lists given to `--k` and `--cal-fraction`/`--cal-queries` make an ablation: the
//! protocol runs once per combination ([`qtvpr::ablation`]) and reports one row per
//! setting. All numbers come from `qtvpr::evaluate`, and the JSON is the core's
//! serialisation of its results (keys: `qtvpr::Report`, semantics §9); this module only reads and
//! formats.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::Args;
use qtvpr::Report;
use qtvpr::{Ablation, MethodResult};
use qtvpr::{Matching, Method, Options, Protocol, ScoresView, Split};

use crate::args::{DescriptorFiles, MatchingArg, SequenceGateArgs};
use crate::embedded;
use crate::gt_source::EvalGtSource;
use crate::output::emit;
use crate::plot;
use crate::summary::{Run, RunContext, ablation_setting, describe, fmt_num};
use qtvpr::npy::read_scores;

/// Arguments of `evaluate`.
#[derive(Debug, Args)]
pub struct EvaluateArgs {
    /// Similarity matrix (.npy, float32/float64), |DB| x |Q|, with ground truth for
    /// every query. Default: the embedded demo data (VPR-Bench Corridor, AMOSNet,
    /// 111 x 111).
    #[arg(long, value_name = "S.npy", requires = "gt-source", group = "scores")]
    similarity: Option<PathBuf>,
    /// Database descriptors (.npy, float32/float64), |DB| x D, in place of
    /// --similarity: the similarity matrix (cosine of L2-normalised rows, as
    /// `similarity` computes it) is computed in memory, never written (the protocol
    /// needs every segment for several methods and the oracle).
    #[arg(
        long,
        value_name = "DB.npy",
        requires_all = ["gt-source", "query_descriptors"],
        group = "scores",
        conflicts_with = "query_major"
    )]
    db_descriptors: Option<PathBuf>,
    /// Query descriptors (.npy), |Q| x D, with --db-descriptors.
    #[arg(long, value_name = "Q.npy", requires = "db_descriptors")]
    query_descriptors: Option<PathBuf>,
    /// With descriptors: sequence-match the similarity over L frames (odd, >= 1) before
    /// the protocol, as `similarity --sequence L` does.
    #[arg(long, value_name = "L", allow_negative_numbers = true, requires = "db_descriptors")]
    sequence: Option<i64>,
    /// Ground truth of --similarity: --gt, --gt-tolerance or --gt-db-positions.
    #[command(flatten)]
    gt: EvalGtSource,
    /// Matrices are stored query-major, |Q| x |DB| (the VPR-Bench convention).
    /// VPR-Bench files are query-major; a square matrix cannot be detected, so pass
    /// this flag for them.
    #[arg(long)]
    query_major: bool,
    /// Methods to evaluate, comma-separated, or `all` (every method that applies to
    /// --matching): quantile-transfer, quantile-transfer-online (each query at the
    /// threshold of its last segment-size queries), quantile-transfer-margin and margin
    /// (quantile transfer with the margin gate, and the gate alone; semantics §13),
    /// quantile-transfer-sequence, quantile-transfer-margin-sequence and sequence
    /// (quantile transfer with the sequence gate, with both gates, and the sequence gate
    /// alone; semantics §15; the gated methods are single matching's only), schubert,
    /// schubert-calibrated, calibration-threshold, oracle.
    #[arg(long, value_delimiter = ',', default_value = "all", value_name = "M1,M2,...")]
    method: Vec<String>,
    /// The sequence gate's parameters, of the sequence methods and of the consistency
    /// reported as a signal (the queries are one traverse, in column order).
    #[command(flatten)]
    sequence_gate: SequenceGateArgs,
    /// Calibration queries sampled per deployment query by quantile transfer. A list
    /// (e.g. 1,3,5,10,20,40) runs one evaluation per value (an ablation).
    #[arg(long, value_delimiter = ',', default_values_t = [qtvpr::DEFAULT_K], value_name = "K1,K2,...")]
    k: Vec<usize>,
    /// Target precision tau, in (0, 1].
    #[arg(long, default_value_t = qtvpr::DEFAULT_PRECISION, allow_negative_numbers = true)]
    precision: f64,
    /// single: one decision per query on its best match; multi: every entry is a candidate.
    #[arg(long, value_enum, default_value_t = MatchingArg::Single)]
    matching: MatchingArg,
    /// The first floor(F x |Q|) queries calibrate. A list (e.g. 0.01,0.05,0.1,0.2,0.3,0.5)
    /// is an ablation.
    #[arg(
        long,
        value_delimiter = ',',
        default_values_t = [qtvpr::DEFAULT_CAL_FRACTION],
        conflicts_with = "cal_queries",
        allow_negative_numbers = true,
        value_name = "F1,F2,..."
    )]
    cal_fraction: Vec<f64>,
    /// The first N queries calibrate (instead of --cal-fraction); a list is an ablation.
    #[arg(long, value_delimiter = ',', value_name = "N1,N2,...")]
    cal_queries: Vec<usize>,
    /// Segments of ceil(F x |Q|) deployment queries (a fraction of all queries).
    #[arg(
        long,
        default_value_t = qtvpr::DEFAULT_SEGMENT_FRACTION,
        conflicts_with = "segment_size",
        allow_negative_numbers = true,
        value_name = "F"
    )]
    segment_fraction: f64,
    /// Segments of M deployment queries (instead of --segment-fraction).
    #[arg(long, value_name = "M")]
    segment_size: Option<usize>,
    /// Deploy on the last floor(F x |Q|) queries only; the queries between the
    /// calibration and deployment sets are unused. Default: every query after the
    /// calibration set, except in an ablation (more than one --k or calibration size),
    /// where it is 0.5: the deployment set is then the same for every setting (the
    /// paper's Fig. 5 protocol), while the calibration set is the first queries.
    #[arg(long, allow_negative_numbers = true, value_name = "F")]
    deploy_fraction: Option<f64>,
    /// Output format: `table`, what a person reads (the summary of every method, the
    /// same in a terminal, a pipe and a file); `json` for every figure (each segment's
    /// counts and thresholds, the reliability bins) to a program; `csv`, one row per
    /// method.
    #[arg(long, value_enum, default_value_t = EvalFormat::Table)]
    format: EvalFormat,
    /// Write to this file (atomically) instead of stdout.
    #[arg(long, short, value_name = "FILE")]
    output: Option<PathBuf>,
    /// Write SVG figures into this directory (created if need be): thresholds.svg,
    /// precision_recall.svg, scores.svg and (single matching) reliability.svg for one
    /// setting; ablation_k.svg / ablation_cal.svg for an ablation.
    #[arg(long, value_name = "DIR")]
    plot: Option<PathBuf>,
}

/// Output formats of `evaluate`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum EvalFormat {
    /// A Markdown table per run, what a person reads (the default).
    Table,
    /// One JSON object with every figure (keys: docs/cli.md and semantics §9); a
    /// reject-all threshold is `null`.
    Json,
    /// One CSV row per method (and per ablation setting).
    Csv,
}

/// The methods `names` asks for, `all` being `all` (the core's list of the methods
/// that apply: [`Method::all_for`] before the input is read, then
/// [`Method::all_applying`] to it).
fn methods_of(names: &[String], all: impl Fn() -> Vec<Method>) -> Result<Vec<Method>> {
    let mut out = Vec::new();
    for name in names {
        let name = name.trim();
        if name == "all" {
            out.extend(all());
        } else {
            out.push(name.parse::<Method>()?);
        }
    }
    if out.is_empty() {
        bail!("no method given");
    }
    Ok(out)
}

/// Run `evaluate`.
pub fn run(args: &EvaluateArgs, global: &crate::Global) -> Result<()> {
    // Checked before any file is read; `all` is resolved again on the input below.
    methods_of(&args.method, || Method::all_for(args.matching.into())).context("--method")?;
    let calibrations: Vec<Split> = if args.cal_queries.is_empty() {
        args.cal_fraction.iter().map(|&f| Split::Fraction(f)).collect()
    } else {
        args.cal_queries.iter().map(|&n| Split::Count(n)).collect()
    };
    let ablation = args.k.len() > 1 || calibrations.len() > 1;
    let matching = Matching::from(args.matching);
    let segment = match args.segment_size {
        Some(m) => Split::Count(m),
        None => Split::Fraction(args.segment_fraction),
    };
    let base = Protocol::resolve(
        Some(args.k[0]),
        Some(args.precision),
        Some(matching),
        Some(calibrations[0]),
        Some(segment),
        args.deploy_fraction,
        args.sequence_gate.overrides(),
    )?;
    // Every setting first, so that a typo fails before any file is read (an ablation's
    // deployment set is the last half unless --deploy-fraction says otherwise).
    base.ablation(&args.k, &calibrations)?;

    let sequence = crate::args::sequence(args.sequence, false)?;

    // The scores stay where they are read (memory-mapped) or embedded; `scores` views them.
    let (file, embedded_scores, computed);
    // Embedded data is |DB| x |Q| whatever --query-major says.
    let query_major = args.query_major && args.similarity.is_some();
    let descriptors = args.db_descriptors.as_ref().zip(args.query_descriptors.as_ref());
    let (dataset, scores, gt) = match (&args.similarity, descriptors, args.gt.source()) {
        (None, Some((db, q)), Some(source)) => {
            computed = similarity_of(db, q, sequence)?;
            let gt = source.load(computed.dim(), false)?;
            (
                format!("{} x {}", db.display(), q.display()),
                ScoresView::F32(computed.view()),
                gt,
            )
        }
        (Some(s_path), _, Some(source)) => {
            file = read_scores(s_path).context("--similarity")?;
            let s = file.view().oriented(query_major);
            let gt = source.load(s.dim(), query_major)?;
            (s_path.display().to_string(), s, gt)
        }
        _ => {
            let (s, gt) = embedded::corridor()?;
            embedded_scores = s;
            (embedded::NAME.to_string(), ScoresView::F64(embedded_scores.view()), gt)
        }
    };
    // What was assumed of a matrix file's orientation, and what its ground truth says
    // (descriptors and the embedded data have but one).
    let orientation = args.similarity.as_ref().map(|_| {
        let from_file = args.gt.source().is_some_and(|g| g.is_file());
        qtvpr::Orientation::of(scores.dim(), from_file.then_some(&gt), query_major)
    });
    let input = || match (&args.similarity, descriptors, args.gt.source()) {
        (Some(s), _, Some(g)) => format!("--similarity {} / {}", s.display(), g.describe()),
        (_, Some((db, q)), Some(g)) => format!(
            "--db-descriptors {} / --query-descriptors {} / {}",
            db.display(),
            q.display(),
            g.describe()
        ),
        _ => "embedded data".to_string(),
    };

    let all = || Method::all_applying(matching, scores.dim().0, &base.sequence_gate);
    let methods = methods_of(&args.method, all).context("--method")?;
    let bar = crate::progress::bar(global.quiet, methods.len(), "method evaluations");
    let progress = |done: usize, total: usize| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    };
    let runs: Vec<Run> = if ablation {
        let options = Options::new(base).progress(&progress);
        let a = qtvpr::ablation(scores, &gt, options, &args.k, &calibrations, &methods)
            .map_err(|e| crate::args::oriented(e, query_major))
            .with_context(input)?;
        a.runs.into_iter().map(Run::from).collect()
    } else {
        let eval = qtvpr::evaluate(scores, &gt, Options::new(base).progress(&progress), &methods)
            .map_err(|e| crate::args::oriented(e, query_major))
            .with_context(input)?;
        vec![Run::from(eval)]
    };
    bar.finish_and_clear();
    // Warned once the result stands, so that a failure stays one `error:` line.
    if let Some(o) = &orientation {
        crate::args::warn_orientation(o);
    }
    let ctx = RunContext {
        dataset,
        database_size: gt.dim().0,
        precision: args.precision,
        matching,
        orientation,
    };

    if let Some(dir) = &args.plot {
        plot::write_all(dir, &ctx, &runs, args.k.len() > 1, calibrations.len() > 1)
            .with_context(|| format!("--plot {}", dir.display()))?;
    }
    let text = match args.format {
        EvalFormat::Json => json(&ctx, runs, ablation)?,
        EvalFormat::Table => table(&ctx, &runs, ablation),
        EvalFormat::Csv => csv(&runs),
    };
    emit(&text, args.output.as_deref())
}

/// The similarity of descriptor files `db` and `q`, in memory (the core's kernel, so
/// the bits of `similarity`'s output), sequence-matched if asked.
fn similarity_of(db: &Path, q: &Path, sequence: Option<qtvpr::Sequence>) -> Result<ndarray::Array2<f32>> {
    let files = DescriptorFiles::read(db, q)?;
    let d = files.descriptors()?;
    let s = d.similarity(0..d.shape().1)?;
    match sequence {
        Some(sequence) => Ok(qtvpr::sequence_match(s.view(), sequence).context("--sequence")?),
        None => Ok(s),
    }
}

/// The JSON document: the core's serialisation of the run or the ablation, with the
/// dataset's name.
fn json(ctx: &RunContext, runs: Vec<Run>, ablation: bool) -> Result<String> {
    let dataset = Some(ctx.dataset.as_str());
    let text = if ablation {
        let result = Ablation {
            runs: runs.into_iter().map(|r| r.eval).collect(),
        };
        serde_json::to_string_pretty(&Report {
            dataset,
            orientation: ctx.orientation,
            result: &result,
        })?
    } else {
        serde_json::to_string_pretty(&Report {
            dataset,
            orientation: ctx.orientation,
            result: &runs[0].eval,
        })?
    };
    Ok(text + "\n")
}

// ---------------------------------------------------------------------------------------
// Markdown table and CSV
// ---------------------------------------------------------------------------------------

fn pct(x: Option<f64>) -> String {
    x.map_or("n/a".into(), |v| format!("{v:.1}"))
}

fn recall(x: Option<f64>) -> String {
    x.map_or("n/a".into(), |v| format!("{v:.3}"))
}

fn mse(x: Option<f64>) -> String {
    x.map_or("n/a".into(), |v| format!("{v:.2e}"))
}

/// A precision (or its lower bound) to three places; `n/a` when nothing is accepted.
fn precision(x: Option<f64>) -> String {
    x.map_or("n/a".into(), |v| format!("{v:.3}"))
}

fn calibration_label(run: &Run) -> String {
    match run.calibration {
        Split::Fraction(f) => format!("{} ({})", fmt_num(f), run.eval.layout.calibration_queries),
        Split::Count(n) => n.to_string(),
    }
}

/// The table's line naming how a similarity file was read (none for descriptors and
/// the embedded data), under the heading of a run or of an ablation.
fn orientation_line(t: &mut String, ctx: &RunContext) {
    if let Some(o) = &ctx.orientation {
        writeln!(t, "orientation: {}\n", o.describe(crate::args::QUERY_MAJOR)).unwrap();
    }
}

fn table(ctx: &RunContext, runs: &[Run], ablation: bool) -> String {
    let avg = ctx.avg_recall_name();
    let mut t = String::new();
    if !ablation {
        let run = &runs[0];
        writeln!(t, "*{}*\n", describe(ctx, run)).unwrap();
        orientation_line(&mut t, ctx);
        writeln!(
            t,
            "| method | %Segs | {avg} | segments counted | skipped (no positives) | threshold MSE vs oracle \
             | matches accepted | pooled precision | its 95% lower bound |"
        )
        .unwrap();
        writeln!(t, "|:--|--:|--:|--:|--:|--:|--:|--:|--:|").unwrap();
        for m in &run.eval.methods {
            let pooled = m.pooled();
            writeln!(
                t,
                "| {} | {} | {} | {} | {} | {} | {} | {} | {} |",
                m.method,
                pct(m.pct_segs),
                recall(m.avg_recall),
                m.segments_counted,
                m.segments_skipped,
                mse(m.threshold_mse),
                pooled.accepted(),
                precision(pooled.measured_precision()),
                precision(pooled.precision_lower95())
            )
            .unwrap();
        }
        // Semantics §14's signals, in single matching.
        if let Some(c) = &run.eval.confidence {
            writeln!(t, "\n| signal | AUROC | Brier | ECE |\n|:--|--:|--:|--:|").unwrap();
            writeln!(t, "| score | {} | | |", recall(c.score_auroc)).unwrap();
            writeln!(t, "| margin | {} | | |", recall(c.margin_auroc)).unwrap();
            writeln!(t, "| pa_score | {} | | |", recall(c.pa_score_auroc)).unwrap();
            writeln!(t, "| consistency | {} | | |", recall(c.consistency_auroc)).unwrap();
            writeln!(
                t,
                "| confidence | {} | {} | {} |",
                recall(c.confidence_auroc),
                recall(c.brier),
                recall(c.ece)
            )
            .unwrap();
        }
        return t;
    }
    writeln!(
        t,
        "*{}: ablation; deployment set: {}. Cells: %Segs / {avg}.*\n",
        ctx.dataset,
        ablation_setting(ctx, &runs[0])
    )
    .unwrap();
    orientation_line(&mut t, ctx);
    let methods: Vec<Method> = runs[0].eval.methods.iter().map(|m| m.method).collect();
    write!(t, "| k | calibration queries |").unwrap();
    for m in &methods {
        write!(t, " {m} |").unwrap();
    }
    write!(t, "\n|--:|--:|").unwrap();
    for _ in &methods {
        write!(t, "--:|").unwrap();
    }
    t.push('\n');
    for run in runs {
        write!(t, "| {} | {} |", run.k, calibration_label(run)).unwrap();
        for m in &run.eval.methods {
            write!(t, " {} / {} |", pct(m.pct_segs), recall(m.avg_recall)).unwrap();
        }
        t.push('\n');
    }
    t
}

fn opt(x: Option<f64>) -> String {
    x.map_or(String::new(), |v| v.to_string())
}

/// Semantics §14's signals of a run as CSV cells (empty in multi matching).
fn signals(c: Option<&qtvpr::Signals>) -> String {
    c.map(qtvpr::Signals::figures).unwrap_or_default().map(opt).join(",")
}

fn csv(runs: &[Run]) -> String {
    let mut t = String::from(
        "k,calibration_queries,deployment_start,deployment_queries,segment_size,segments,method,\
         pct_segs,avg_recall,segments_counted,segments_skipped,threshold_mse,pooled_accepted,pooled_precision,\
         pooled_recall,\
         pooled_precision_lower95,recall_at_1,",
    );
    t += &qtvpr::Signals::FIGURES.join(",");
    t.push('\n');
    for run in runs {
        let l = run.eval.layout;
        for m in &run.eval.methods {
            let MethodResult {
                method,
                pct_segs,
                avg_recall,
                segments_counted,
                segments_skipped,
                threshold_mse,
                ..
            } = m;
            let pooled = m.pooled();
            writeln!(
                t,
                "{},{},{},{},{},{},{method},{},{},{segments_counted},{segments_skipped},{},{},{},{},{},{},{}",
                run.k,
                l.calibration_queries,
                l.deployment_start,
                l.deployment_queries,
                l.segment_size,
                l.segments,
                opt(*pct_segs),
                opt(*avg_recall),
                opt(*threshold_mse),
                pooled.accepted(),
                opt(pooled.measured_precision()),
                pooled.recall(),
                opt(pooled.precision_lower95()),
                opt(run.eval.recall_at_1),
                signals(run.eval.confidence.as_ref())
            )
            .unwrap();
        }
    }
    t
}
