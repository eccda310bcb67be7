//! `qtvpr-cli similarity`: the similarity matrix from descriptor files, optionally
//! sequence-matched. The arithmetic is the core's ([`qtvpr::cosine_similarity`],
//! [`qtvpr::sequence_match`]).

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;
use qtvpr::Input;
use qtvpr::npy::{FloatMatrix, read_float_matrix};
use qtvpr::{Descriptors, Options};

use crate::args::blame;
use crate::output::write_npy;
use crate::{Global, progress};

/// Arguments of `similarity`.
#[derive(Debug, Args)]
pub struct SimilarityArgs {
    /// Database descriptors (.npy, float32/float64), |DB| x D, one image per row (e.g.
    /// VPR-methods-evaluation's database_descriptors.npy).
    #[arg(long, value_name = "DB.npy")]
    db: PathBuf,
    /// Query descriptors (.npy), |Q| x D (e.g. queries_descriptors.npy).
    #[arg(long, value_name = "Q.npy")]
    queries: PathBuf,
    /// Sequence matching over L frames (odd, >= 1), an extension beyond the paper:
    /// S_seq[i, j] is the mean of S[i+d, j+d] for d in -(L-1)/2 ..= (L-1)/2, over the
    /// entries inside the matrix (SeqSLAM at velocity 1; for traverses in the same
    /// direction at a similar frame rate).
    #[arg(long, value_name = "L", allow_negative_numbers = true)]
    sequence: Option<i64>,
    /// With --sequence: average the current frame and the L-1 before it only
    /// (d in -(L-1) ..= 0), as a robot would online.
    #[arg(long, requires = "sequence")]
    causal: bool,
    /// Where to write the similarity matrix: .npy, float32, |DB| x |Q| (atomically).
    #[arg(long, short, value_name = "S.npy")]
    output: PathBuf,
}

/// Run `similarity`.
pub fn run(args: &SimilarityArgs, global: &Global) -> Result<()> {
    // Check the cheap parameter before reading anything.
    let sequence = crate::args::sequence(args.sequence, args.causal)?;
    let db = read_float_matrix(&args.db, FloatMatrix::Descriptors).context("--db")?;
    let queries = read_float_matrix(&args.queries, FloatMatrix::Descriptors).context("--queries")?;
    let sources = [
        (Input::DbDescriptors, format!("--db {}", args.db.display())),
        (Input::QueryDescriptors, format!("--queries {}", args.queries.display())),
    ];
    let bar = progress::bar(global.quiet, db.view().dim().0, "database rows");
    let progress = |done: usize, _| bar.set_position(done as u64);
    let s = Descriptors::new(db.view(), queries.view())
        .and_then(|d| d.similarity(Options::new(0..d.shape().1).progress(&progress)))
        .map_err(|e| blame(e, &sources))?;
    bar.finish_and_clear();
    drop((db, queries));
    let s = match sequence {
        Some(sequence) => qtvpr::sequence_match(s.view(), sequence).context("--sequence")?,
        None => s,
    };
    write_npy(&args.output, "--output", s.view())
}
