//! End-to-end tests of ground truth from image names (`--db-images` / `--query-images`
//! and their `--gt-` and `--cal-gt-` forms): the same ground truth as from position
//! files, errors naming the list and the line, and the VPR-methods-evaluation on-ramp
//! on the Nordland HOG descriptors (`../shared/data/nordland-hog`).

use std::path::{Path, PathBuf};

use tempfile::TempDir;

use crate::common::{assert_clean_failure, npy_f64, ok_in, run_in};
use qtvpr_testkit::data;

/// A VPR-methods-evaluation-style folder: `database/` and `queries/` of empty images
/// named `@east@north@...@.jpg`.
struct Folder(TempDir);

impl Folder {
    fn new() -> Self {
        Self(tempfile::tempdir().unwrap())
    }

    fn path(&self, name: &str) -> PathBuf {
        self.0.path().join(name)
    }

    /// Empty files `dir/NAME` for each name.
    fn images(&self, dir: &str, names: &[String]) {
        let dir = self.path(dir);
        std::fs::create_dir_all(&dir).unwrap();
        for name in names {
            let path = dir.join(name);
            std::fs::create_dir_all(path.parent().unwrap()).unwrap();
            std::fs::write(path, b"").unwrap();
        }
    }

    fn ok(&self, args: &[&str]) -> String {
        ok_in(self.0.path(), args)
    }

    fn fails(&self, args: &[&str], outputs: &[&str], needles: &[&str]) {
        let out = run_in(self.0.path(), args);
        let outputs: Vec<PathBuf> = outputs.iter().map(|o| self.path(o)).collect();
        let outputs: Vec<&Path> = outputs.iter().map(PathBuf::as_path).collect();
        assert_clean_failure(&out, self.0.path(), &outputs, needles);
    }

    fn read(&self, name: &str) -> Vec<u8> {
        std::fs::read(self.path(name)).unwrap()
    }
}

fn names(points: &[(f64, f64)]) -> Vec<String> {
    points
        .iter()
        .map(|(e, n)| format!("@{e}@{n}@33@W@0@0@pano@.jpg"))
        .collect()
}

/// Queries at (0, 0) and (10, 0); database at (3, 4), (7, 0), (10, -5). Radius 5, soft 8:
/// db (3, 4): distances 5 (hard) and sqrt(49 + 16) = 8.06 (neither);
/// db (7, 0): 7 (soft) and 3 (hard); db (10, -5): sqrt(100 + 25) = 11.2 and 5 (hard).
/// Sorted by name, the database is "@10@-5@..." < "@3@4@..." < "@7@0@..." ('1' < '3' < '7').
fn small_case() -> Folder {
    let f = Folder::new();
    f.images("database", &names(&[(3.0, 4.0), (7.0, 0.0), (10.0, -5.0)]));
    f.images("queries", &names(&[(0.0, 0.0), (10.0, 0.0)]));
    // The same positions in the order of the sorted names.
    npy_f64(&f.path("dbp.npy"), &[&[10.0, -5.0], &[3.0, 4.0], &[7.0, 0.0]]);
    npy_f64(&f.path("qp.npy"), &[&[0.0, 0.0], &[10.0, 0.0]]);
    f
}

#[test]
fn ground_truth_from_names_equals_ground_truth_from_positions() {
    let f = small_case();
    let common = ["ground-truth", "--radius", "5", "--soft-radius", "8"];
    f.ok(&[
        &common[..],
        &["--db-images", "database", "--query-images", "queries", "-o", "a.npz"],
    ]
    .concat());
    f.ok(&[
        &common[..],
        &[
            "--db-positions",
            "dbp.npy",
            "--query-positions",
            "qp.npy",
            "-o",
            "b.npz",
        ],
    ]
    .concat());
    assert_eq!(f.read("a.npz"), f.read("b.npz"));
    let hard = crate::common::npz_bools(&f.path("a.npz"), "GThard");
    let soft = crate::common::npz_bools(&f.path("a.npz"), "GTsoft");
    // Rows (10, -5), (3, 4), (7, 0), see small_case.
    let t = true;
    assert_eq!(hard, [!t, t, t, !t, !t, t]);
    assert_eq!(soft, [!t, t, t, !t, t, t]);

    // A text file gives its own order: the rows (7, 0), (10, -5).
    std::fs::write(
        f.path("db.txt"),
        "database/@7@0@33@W@0@0@pano@.jpg\ndatabase/@10@-5@33@W@0@0@pano@.jpg\n",
    )
    .unwrap();
    f.ok(&[
        "ground-truth",
        "--db-images",
        "db.txt",
        "--query-images",
        "queries",
        "--radius",
        "5",
        "-o",
        "c.npy",
    ]);
    npy_f64(&f.path("dbp2.npy"), &[&[7.0, 0.0], &[10.0, -5.0]]);
    f.ok(&[
        "ground-truth",
        "--db-positions",
        "dbp2.npy",
        "--query-positions",
        "qp.npy",
        "--radius",
        "5",
        "-o",
        "d.npy",
    ]);
    assert_eq!(f.read("c.npy"), f.read("d.npy"));
}

#[test]
fn the_radius_of_names_defaults_to_25_metres() {
    let f = Folder::new();
    // Database at east 25 and 25.5 from the query at 0: 25 <= 25 matches, 25.5 does not.
    // Names sort byte by byte: "@25.5@..." before "@25@..." ('.' is 0x2E, '@' 0x40).
    f.images("database", &names(&[(25.0, 0.0), (25.5, 0.0)]));
    f.images("queries", &names(&[(0.0, 0.0)]));
    f.ok(&[
        "ground-truth",
        "--db-images",
        "database",
        "--query-images",
        "queries",
        "-o",
        "a.npy",
    ]);
    npy_f64(&f.path("dbp.npy"), &[&[25.5, 0.0], &[25.0, 0.0]]);
    npy_f64(&f.path("qp.npy"), &[&[0.0, 0.0]]);
    f.ok(&[
        "ground-truth",
        "--db-positions",
        "dbp.npy",
        "--query-positions",
        "qp.npy",
        "--radius",
        "25",
        "-o",
        "b.npy",
    ]);
    assert_eq!(f.read("a.npy"), f.read("b.npy"));
    let hard: Vec<bool> = npyz::NpyFile::new(&f.read("a.npy")[..]).unwrap().into_vec().unwrap();
    assert_eq!(hard, [false, true]);
}

#[test]
fn evaluate_and_threshold_take_names_as_they_take_positions() {
    let f = small_case();
    // Similarity 3 x 2 (database rows in the sorted order of small_case).
    npy_f64(&f.path("s.npy"), &[&[0.2, 0.9], &[0.8, 0.1], &[0.3, 0.7]]);
    let evaluate = |gt: &[&str], out: &str| {
        let base = [
            "evaluate",
            "--similarity",
            "s.npy",
            "--cal-queries",
            "1",
            "--segment-size",
            "1",
            "-o",
            out,
        ];
        f.ok(&[&base[..], gt].concat());
        f.read(out)
    };
    let from_positions = evaluate(
        &[
            "--gt-db-positions",
            "dbp.npy",
            "--gt-query-positions",
            "qp.npy",
            "--gt-radius",
            "5",
        ],
        "a.json",
    );
    assert_eq!(
        evaluate(
            &[
                "--gt-db-images",
                "database",
                "--gt-query-images",
                "queries",
                "--gt-radius",
                "5"
            ],
            "b.json"
        ),
        from_positions
    );
    // evaluate's one ground truth also takes the short names.
    assert_eq!(
        evaluate(
            &["--db-images", "database", "--query-images", "queries", "--radius", "5"],
            "c.json"
        ),
        from_positions
    );

    let threshold = |gt: &[&str], out: &str| {
        let base = [
            "threshold",
            "--cal",
            "s.npy",
            "--val",
            "s.npy",
            "--k",
            "1",
            "--format",
            "csv",
            "-o",
            out,
        ];
        f.ok(&[&base[..], gt].concat());
        f.read(out)
    };
    assert_eq!(
        threshold(
            &[
                "--cal-gt-db-images",
                "database",
                "--cal-gt-query-images",
                "queries",
                "--cal-gt-radius",
                "5"
            ],
            "a.csv"
        ),
        threshold(
            &[
                "--cal-gt-db-positions",
                "dbp.npy",
                "--cal-gt-query-positions",
                "qp.npy",
                "--cal-gt-radius",
                "5"
            ],
            "b.csv"
        ),
    );
    f.ok(&[
        "calibrate",
        "--cal",
        "s.npy",
        "--cal-gt-db-images",
        "database",
        "--cal-gt-query-images",
        "queries",
        "-o",
        "c.npz",
    ]);
}

#[test]
fn bad_lists_name_the_list_and_the_line() {
    let f = small_case();
    npy_f64(&f.path("s.npy"), &[&[0.2, 0.9], &[0.8, 0.1], &[0.3, 0.7]]);
    let gt = |db: &str, q: &str, needles: &[&str]| {
        f.fails(
            &["ground-truth", "--db-images", db, "--query-images", q, "-o", "gt.npy"],
            &["gt.npy"],
            needles,
        );
    };
    std::fs::write(f.path("bad.txt"), "@1@2@.jpg\n@3@4@.jpg\nq/img_0003.jpg\n").unwrap();
    gt(
        "bad.txt",
        "queries",
        &["--db-images bad.txt: bad.txt line 3: image name 'q/img_0003.jpg' has fewer than two '@'"],
    );
    std::fs::write(f.path("gap.txt"), "@1@2@.jpg\n\n@3@4@.jpg\n").unwrap();
    gt(
        "database",
        "gap.txt",
        &["--query-images gap.txt: gap.txt line 2 is empty"],
    );
    std::fs::write(f.path("nan.txt"), "@1@nan@.jpg\n").unwrap();
    gt(
        "nan.txt",
        "queries",
        &["nan.txt line 1: image name '@1@nan@.jpg' has utm_north 'nan', which is not finite"],
    );
    std::fs::create_dir(f.path("empty")).unwrap();
    std::fs::write(f.path("empty/notes.txt"), "").unwrap();
    gt("empty", "queries", &["--db-images empty: empty contains no images"]);
    gt("missing", "queries", &["--db-images missing: cannot read missing"]);
    f.images("bad_dir", &["@1@2@.jpg".into(), "sub/photo.jpg".into()]);
    gt(
        "bad_dir",
        "queries",
        &["--db-images bad_dir: bad_dir: image name 'bad_dir/sub/photo.jpg' has fewer"],
    );

    // A list of the wrong length names the list and both counts.
    let eval = |extra: &[&str], needles: &[&str]| {
        let base = [
            "evaluate",
            "--similarity",
            "s.npy",
            "--cal-queries",
            "1",
            "--segment-size",
            "1",
            "-o",
            "e.json",
        ];
        f.fails(&[&base[..], extra].concat(), &["e.json"], needles);
    };
    eval(
        &["--db-images", "queries", "--query-images", "queries"],
        &["--gt-db-images queries: lists 2 images but the similarity matrix has 3 database images"],
    );
    eval(
        &["--db-images", "database", "--query-images", "database"],
        &["--gt-query-images database: lists 3 images but the similarity matrix has 2 queries"],
    );
    // With a split, the calibration ground truth labels every query of the one matrix.
    f.fails(
        &[
            "threshold",
            "--similarity",
            "s.npy",
            "--cal-queries",
            "1",
            "--cal-gt-db-images",
            "database",
            "--cal-gt-query-images",
            "database",
            "-o",
            "t.json",
        ],
        &["t.json"],
        &["--cal-gt-query-images database: lists 3 images but the similarity it labels has 2 queries"],
    );
    eval(
        &["--db-images", "database", "--query-images", "queries", "--radius", "-1"],
        &["--gt-radius", "radius must be a finite number >= 0, got -1"],
    );
    // Names and positions are two sources: one at a time (a usage error, exit 2).
    let out = run_in(
        f.0.path(),
        &[
            "ground-truth",
            "--db-images",
            "database",
            "--query-images",
            "queries",
            "--db-positions",
            "dbp.npy",
            "--query-positions",
            "qp.npy",
            "--radius",
            "1",
            "-o",
            "gt.npy",
        ],
    );
    assert_eq!(out.status.code(), Some(2));
    assert!(!f.path("gt.npy").exists());
}

/// The Nordland HOG descriptors as a VPR-methods-evaluation output folder: query j and
/// database image j show the same place (../shared/data/README.md), so place j is put at
/// UTM (500000 + 20 j, 7000000), the queries 3 m north of it. Within the default 25 m,
/// query j then matches database images j-1, j, j+1 exactly: distances 3,
/// sqrt(20² + 3²) = 20.2, and, two places apart, sqrt(40² + 3²) = 40.1. That is the
/// dataset's truth, |i - j| <= 1. All easts have 6 digits, so sorting the names sorts
/// the places.
fn nordland_folder() -> Option<Folder> {
    let (db, q) = (
        data::shared("nordland-hog/db_winter.npy")?,
        data::shared("nordland-hog/query_summer.npy")?,
    );
    let f = Folder::new();
    let n = 3576;
    let place = |j: usize, north: f64| (500_000.0 + 20.0 * j as f64, north);
    f.images(
        "database",
        &names(&(0..n).map(|j| place(j, 7_000_000.0)).collect::<Vec<_>>()),
    );
    f.images(
        "queries",
        &names(&(0..n).map(|j| place(j, 7_000_003.0)).collect::<Vec<_>>()),
    );
    std::fs::copy(db, f.path("database_descriptors.npy")).unwrap();
    std::fs::copy(q, f.path("queries_descriptors.npy")).unwrap();
    Some(f)
}

#[test]
#[ignore = "needs ../shared/data nordland-hog: a VPR-methods-evaluation folder, 3576 images each side"]
fn vpr_methods_evaluation_folder_to_the_evaluate_table() {
    let Some(f) = nordland_folder() else {
        return;
    };
    f.ok(&[
        "similarity",
        "--db",
        "database_descriptors.npy",
        "--queries",
        "queries_descriptors.npy",
        "-o",
        "S.npy",
    ]);
    let table = f.ok(&[
        "evaluate",
        "--similarity",
        "S.npy",
        "--db-images",
        "database",
        "--query-images",
        "queries",
        "--format",
        "table",
    ]);
    let by_tolerance = f.ok(&[
        "evaluate",
        "--similarity",
        "S.npy",
        "--gt-tolerance",
        "1",
        "--format",
        "table",
    ]);
    assert_eq!(table, by_tolerance);
    assert!(table.contains("quantile-transfer"), "{table}");
}

/// The on-ramp in one command: descriptors and image names to the evaluation table, the
/// table of `similarity` followed by `evaluate --similarity` with the dataset's truth.
#[test]
#[ignore = "needs ../shared/data nordland-hog: a VPR-methods-evaluation folder, 3576 images each side"]
fn vpr_methods_evaluation_folder_in_one_command() {
    let Some(f) = nordland_folder() else {
        return;
    };
    let table = f.ok(&[
        "evaluate",
        "--db-descriptors",
        "database_descriptors.npy",
        "--query-descriptors",
        "queries_descriptors.npy",
        "--db-images",
        "database",
        "--query-images",
        "queries",
        "--format",
        "table",
    ]);
    f.ok(&[
        "similarity",
        "--db",
        "database_descriptors.npy",
        "--queries",
        "queries_descriptors.npy",
        "-o",
        "S.npy",
    ]);
    let by_tolerance = f.ok(&[
        "evaluate",
        "--similarity",
        "S.npy",
        "--gt-tolerance",
        "1",
        "--format",
        "table",
    ]);
    // The header names the inputs (the two descriptor files, or S.npy), and the matrix's
    // orientation follows it (descriptors have but one); the tables agree.
    let body = |t: &str| t.split_once('\n').map(|(_, rest)| rest.to_owned()).unwrap();
    assert!(
        table.starts_with("*database_descriptors.npy x queries_descriptors.npy: 3576 database images"),
        "{table}"
    );
    // A frame tolerance is made for the matrix as read: it cannot tell the layout.
    let orientation = "\norientation: |DB| 3576 x |Q| 3576 (DB-major; pass --query-major for VPR-Bench files), \
                       assumed (no ground truth was read in the matrix's layout to tell)\n";
    let matrix_body = body(&by_tolerance);
    assert!(matrix_body.starts_with(orientation), "{by_tolerance}");
    assert_eq!(body(&table), matrix_body.replacen(orientation, "", 1));
}
