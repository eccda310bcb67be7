//! Extension (not a section of the semantics): positions from image names.
//!
//! The large VPR benchmarks (Pitts30k, MSLS, SF-XL, Tokyo 24/7, ... as laid out by
//! VPR-methods-evaluation and the deep visual geo-localization benchmark) carry each
//! image's position in its file name:
//! `@UTM_east@UTM_north@UTM_zone_number@UTM_zone_letter@lat@lon@pano_id@...@.jpg`.
//! This module reads those names into the |N| x 2 position matrices (UTM east, north,
//! in metres) that [`GtSpec::Positions`](crate::extensions::ground_truth::GtSpec::Positions) turns
//! into ground truth within a radius (25 m in those benchmarks), so that no position
//! file has to be written first.
//!
//! - [`utm_position`]: fields 1 and 2 of the **file name** split on `@` (the first field,
//!   before the first `@`, is usually empty). VPR-methods-evaluation splits the whole
//!   path, `path.split("@")[1:3]`; the file name gives the same numbers when no
//!   directory name holds an `@`, and the right ones when one does.
//! - [`image_paths`] (feature `npy`): the images of a dataset folder, in the order
//!   VPR-methods-evaluation gives its descriptor rows, or the lines of a text file.
//!   The order of the names is the order of the rows (database images) and columns
//!   (queries) of the similarity matrix: it must be the order of the descriptor rows.

use std::path::Path;

use ndarray::Array2;

pub use crate::error::NameAt;
use crate::error::{Error, Result};

/// The extensions, compared without regard to ASCII case, of the files of a directory
/// that [`image_paths`] lists: VPR-methods-evaluation's
/// `os.path.splitext(p)[1].lower() in [".jpg", ".jpeg", ".png"]`.
pub const IMAGE_EXTENSIONS: [&str; 3] = ["jpg", "jpeg", "png"];

/// The radius of positions from image names when none is given: 25 m, the positive
/// distance of VPR-methods-evaluation and the benchmarks it evaluates.
pub const DEFAULT_IMAGE_RADIUS: f64 = 25.0;

/// UTM east and north, in metres, from the file name of `path`: fields 1 and 2 of the
/// file name (the last component of the path) split on `@`, each a decimal number
/// (Rust's `f64` syntax: `-12.5`, `+3`, `4e5`; no spaces). A path without a file name
/// (empty, or ending in `..`) is parsed as it is.
///
/// ```
/// use qtvpr::utm_position;
///
/// let p = utm_position("db/@549373.55@4178869.56@10@S@37.7556@-122.4409@.jpg")?;
/// assert_eq!(p, [549373.55, 4178869.56]);
/// # Ok::<(), qtvpr::Error>(())
/// ```
///
/// # Errors
/// [`Error::ImageName`] (at `paths[0]`; [`utm_positions`] names the index) when the
/// name is not UTF-8, has fewer than two `@`, or a field is not a finite number.
pub fn utm_position(path: impl AsRef<Path>) -> Result<[f64; 2]> {
    parse(path.as_ref()).map_err(|problem| name_error(NameAt::Index(0), path.as_ref(), problem))
}

/// The positions of `paths`, one row each: |N| x 2, UTM east and north, by
/// [`utm_position`]. An empty list gives a 0 x 2 matrix.
///
/// # Errors
/// [`Error::ImageName`] at the index (`paths[i]`, 0-based) of the first name that does not parse.
pub fn utm_positions<P: AsRef<Path>>(paths: &[P]) -> Result<Array2<f64>> {
    positions(paths.iter().map(AsRef::as_ref), NameAt::Index)
}

/// The positions of names, with each name's place given by `at(i)`.
fn positions<'p>(paths: impl Iterator<Item = &'p Path>, at: impl Fn(usize) -> NameAt) -> Result<Array2<f64>> {
    let mut flat = Vec::new();
    for (i, path) in paths.enumerate() {
        let [east, north] = parse(path).map_err(|problem| name_error(at(i), path, problem))?;
        flat.extend([east, north]);
    }
    Ok(Array2::from_shape_vec((flat.len() / 2, 2), flat).expect("two values per name"))
}

fn name_error(at: NameAt, path: &Path, problem: String) -> Error {
    Error::ImageName {
        at,
        name: path.display().to_string(),
        problem,
    }
}

/// Fields 1 and 2 of the file name, or what is wrong with it.
fn parse(path: &Path) -> Result<[f64; 2], String> {
    let name = path.file_name().unwrap_or(path.as_os_str());
    let name = name.to_str().ok_or_else(|| "is not valid UTF-8".to_string())?;
    let mut fields = name.split('@').skip(1);
    let (Some(east), Some(north)) = (fields.next(), fields.next()) else {
        return Err("has fewer than two '@'".into());
    };
    let number = |what: &str, field: &str| match field.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(_) => Err(format!("has {what} '{field}', which is not finite")),
        Err(_) => Err(format!("has {what} '{field}', which is not a number")),
    };
    Ok([number("utm_east", east)?, number("utm_north", north)?])
}

/// The image paths a list names, in order, and where they came from: what
/// [`image_paths`] reads. [`ImageList::positions`] parses them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ImageList {
    /// The paths, in the order of the descriptor rows. From a directory, each is the
    /// directory joined with the file's path below it (`database/sub/x.jpg`); from a
    /// text file, each line as written.
    pub paths: Vec<std::path::PathBuf>,
    /// The text file the paths were read from (the list itself, or a directory's
    /// `DIR_images_paths.txt`), if any.
    pub file: Option<std::path::PathBuf>,
    /// The directory the paths were listed from, if any.
    pub dir: Option<std::path::PathBuf>,
}

impl ImageList {
    /// The positions of the paths, |N| x 2 (UTM east, north), by [`utm_position`].
    ///
    /// # Errors
    /// [`Error::ImageName`] at the first name that does not parse: its line in the text
    /// file, or the directory it was found in.
    pub fn positions(&self) -> Result<Array2<f64>> {
        let at = |i: usize| match (&self.file, &self.dir) {
            (Some(file), _) => NameAt::Line {
                file: file.display().to_string(),
                line: i + 1,
            },
            (None, Some(dir)) => NameAt::Directory(dir.display().to_string()),
            (None, None) => NameAt::Index(i),
        };
        positions(self.paths.iter().map(|p| p.as_path()), at)
    }
}

/// The image paths of `list`, a directory or a text file, in the order of the
/// descriptor rows as VPR-methods-evaluation computes them (`read_images_paths` of its
/// `test_dataset.py`):
///
/// - a **directory** `DIR`: if the text file `DIR_images_paths.txt` exists next to it
///   (`DIR` without a trailing `/`, then `_images_paths.txt`), the lines of that file,
///   each joined to `DIR`; otherwise every file (or link to one) in `DIR` and its
///   subdirectories, at any depth, whose extension is one of [`IMAGE_EXTENSIONS`],
///   skipping names that begin with `.` (as Python's `glob` does), sorted by their path
///   below `DIR` with `/` separators, byte by byte (Python's `sorted(glob(...))`: the
///   order of Unicode code points);
/// - a **text file**: one path per line, in order. Lines end in `\n` or `\r\n`; the
///   last may lack it. An empty line is an error, not a skipped row: every line is a
///   row. The paths are not opened (only their names are read), so they may be
///   relative to anything.
///
/// # Errors
/// - [`Error::Io`] when `list` (or a subdirectory, or the text file) cannot be read;
/// - [`Error::File`] for a directory without images, an empty text file, an empty
///   line (naming it, 1-based), or a line that is not UTF-8.
#[cfg(feature = "npy")]
pub fn image_paths(list: impl AsRef<Path>) -> Result<ImageList> {
    let list = list.as_ref();
    let meta = std::fs::metadata(list).map_err(|e| io_error(list, &e))?;
    if !meta.is_dir() {
        return Ok(ImageList {
            paths: read_lines(list, None)?,
            file: Some(list.to_path_buf()),
            dir: None,
        });
    }
    let sidecar = sidecar(list);
    if sidecar.is_file() {
        return Ok(ImageList {
            paths: read_lines(&sidecar, Some(list))?,
            file: Some(sidecar),
            dir: Some(list.to_path_buf()),
        });
    }
    let mut relative = Vec::new();
    let hidden = |e: &walkdir::DirEntry| e.depth() > 0 && e.file_name().as_encoded_bytes().starts_with(b".");
    for entry in walkdir::WalkDir::new(list)
        .follow_links(true)
        .into_iter()
        .filter_entry(|e| !hidden(e))
    {
        let entry = entry.map_err(|e| walk_error(list, &e))?;
        let is_image = entry
            .path()
            .extension()
            .is_some_and(|ext| IMAGE_EXTENSIONS.iter().any(|image| ext.eq_ignore_ascii_case(image)));
        if entry.file_type().is_file() && is_image {
            let below = entry
                .path()
                .strip_prefix(list)
                .expect("walkdir yields paths below its root");
            let components: Vec<&[u8]> = below.iter().map(|c| c.as_encoded_bytes()).collect();
            relative.push(components.join(&b'/'));
        }
    }
    if relative.is_empty() {
        return Err(Error::File {
            path: list.display().to_string(),
            message: "contains no images (files ending in .jpg, .jpeg or .png, any case, at any depth)".into(),
        });
    }
    relative.sort_unstable();
    let paths = relative
        .into_iter()
        .map(|bytes| list.join(bytes_to_path(&bytes)))
        .collect();
    Ok(ImageList {
        paths,
        file: None,
        dir: Some(list.to_path_buf()),
    })
}

/// `DIR_images_paths.txt` next to the directory `dir` (VPR-methods-evaluation's
/// `dataset_folder + "_images_paths.txt"`, without a trailing separator of `dir`).
#[cfg(feature = "npy")]
fn sidecar(dir: &Path) -> std::path::PathBuf {
    let mut name = dir.as_os_str().to_owned();
    let bytes = name.as_encoded_bytes();
    let trimmed = bytes.len() - bytes.iter().rev().take_while(|&&b| b == b'/').count();
    if trimmed < bytes.len() && trimmed > 0 {
        name = bytes_to_path(&bytes[..trimmed]).into_os_string();
    }
    name.push("_images_paths.txt");
    name.into()
}

/// A path from bytes that came out of an `OsStr`'s encoded bytes, cut only at ASCII
/// `/` (so still valid encoded bytes).
#[cfg(feature = "npy")]
fn bytes_to_path(bytes: &[u8]) -> std::path::PathBuf {
    match std::str::from_utf8(bytes) {
        Ok(s) => s.into(),
        Err(_) => {
            #[cfg(unix)]
            {
                use std::os::unix::ffi::OsStrExt;
                std::ffi::OsStr::from_bytes(bytes).into()
            }
            #[cfg(not(unix))]
            {
                String::from_utf8_lossy(bytes).into_owned().into()
            }
        }
    }
}

/// The lines of a text file of paths, each joined to `dir` if given.
#[cfg(feature = "npy")]
fn read_lines(file: &Path, dir: Option<&Path>) -> Result<Vec<std::path::PathBuf>> {
    let bytes = std::fs::read(file).map_err(|e| io_error(file, &e))?;
    let file_error = |message: String| Error::File {
        path: file.display().to_string(),
        message,
    };
    let text = match std::str::from_utf8(&bytes) {
        Ok(text) => text,
        Err(e) => {
            let line = bytes[..e.valid_up_to()].iter().filter(|&&b| b == b'\n').count() + 1;
            return Err(file_error(format!("line {line} is not valid UTF-8")));
        }
    };
    if text.is_empty() {
        return Err(file_error("is empty; it must list one image path per line".into()));
    }
    let text = text.strip_suffix('\n').unwrap_or(text);
    text.split('\n')
        .enumerate()
        .map(|(i, line)| {
            let line = line.strip_suffix('\r').unwrap_or(line);
            if line.is_empty() {
                return Err(file_error(format!(
                    "line {} is empty; every line must be an image path (one per descriptor row)",
                    i + 1
                )));
            }
            Ok(dir.map_or_else(|| line.into(), |d| d.join(line)))
        })
        .collect()
}

#[cfg(feature = "npy")]
fn io_error(path: &Path, e: &std::io::Error) -> Error {
    Error::Io {
        path: path.display().to_string(),
        kind: e.kind(),
        message: e.to_string(),
    }
}

#[cfg(feature = "npy")]
fn walk_error(list: &Path, e: &walkdir::Error) -> Error {
    let path = e.path().unwrap_or(list);
    match e.io_error() {
        Some(io) => io_error(path, io),
        // The one error walkdir has without an I/O error: a link back to an ancestor.
        None => Error::File {
            path: path.display().to_string(),
            message: "is a symbolic link to one of its own parent directories".into(),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_east_and_north_of_the_file_name() {
        // Fields 1 and 2 of "@549373.55@4178869.56@10@S@...@.jpg" split on '@'.
        let p = utm_position("@549373.55@4178869.56@10@S@37.7556@-122.4409@pano@.jpg").unwrap();
        assert_eq!(p, [549373.55, 4178869.56]);
        // Negative, signed, exponent and integer values.
        assert_eq!(utm_position("x/@-12.5@+3@.png").unwrap(), [-12.5, 3.0]);
        assert_eq!(utm_position("@4e5@7@").unwrap(), [400000.0, 7.0]);
        // A directory with '@' in its name does not count: only the file name is split
        // (VPR-methods-evaluation's whole-path split would read "weird" and "dir").
        assert_eq!(utm_position("data/@weird@dir@/@1.5@2.25@.jpg").unwrap(), [1.5, 2.25]);
    }

    #[test]
    fn bad_names_say_why() {
        let message = |name: &str| utm_position(name).unwrap_err().to_string();
        assert_eq!(
            message("d/img.jpg"),
            "paths[0]: image name 'd/img.jpg' has fewer than two '@'; \
             names must look like @utm_east@utm_north@...@.jpg"
        );
        assert_eq!(
            message("@12.jpg"),
            "paths[0]: image name '@12.jpg' has fewer than two '@'; \
             names must look like @utm_east@utm_north@...@.jpg"
        );
        assert!(message("@east@2@.jpg").contains("has utm_east 'east', which is not a number"));
        assert!(message("@1@ 2@.jpg").contains("has utm_north ' 2', which is not a number"));
        assert!(message("@1@nan@.jpg").contains("has utm_north 'nan', which is not finite"));
        assert!(message("@1e999@2@.jpg").contains("has utm_east '1e999', which is not finite"));
        // "@1@2.jpg": field 2 is "2.jpg".
        assert!(message("@1@2.jpg").contains("has utm_north '2.jpg', which is not a number"));
    }

    #[test]
    fn lists_name_the_index_of_a_bad_name() {
        let m = utm_positions(&["@1@2@.jpg", "@-3.5@4@.jpg"]).unwrap();
        assert_eq!(m, ndarray::array![[1.0, 2.0], [-3.5, 4.0]]);
        assert_eq!(utm_positions::<&str>(&[]).unwrap().dim(), (0, 2));
        let e = utm_positions(&["@1@2@.jpg", "@1@2@.jpg", "bad.jpg"]).unwrap_err();
        assert!(e.to_string().starts_with("paths[2]: image name 'bad.jpg' "), "{e}");
        let list = ImageList {
            paths: vec!["@1@2@".into(), "x".into()],
            file: Some("list.txt".into()),
            dir: None,
        };
        let e = list.positions().unwrap_err().to_string();
        assert!(e.starts_with("list.txt line 2: image name 'x' "), "{e}");
    }

    #[cfg(feature = "npy")]
    #[test]
    fn directories_list_images_as_vpr_methods_evaluation_does() {
        let tmp = tempfile::tempdir().unwrap();
        let db = tmp.path().join("database");
        std::fs::create_dir_all(db.join("b")).unwrap();
        std::fs::create_dir_all(db.join(".hidden")).unwrap();
        for name in [
            "@2@0@.jpg",
            "@1@0@.JPG",
            "b/@3@0@.png",
            "b.@4@0@.jpeg",
            ".@9@9@.jpg",
            ".hidden/@9@9@.jpg",
            "@9@9@.txt",
        ] {
            std::fs::write(db.join(name), b"").unwrap();
        }
        // A directory named like an image is not one.
        std::fs::create_dir(db.join("@8@8@.jpg")).unwrap();
        let list = image_paths(&db).unwrap();
        // Sorted by the path below the directory, byte by byte: "@1..." < "@2..." <
        // "b.@4..." < "b/@3..." ('.' is 0x2E, '/' 0x2F); hidden names, other extensions and
        // directories are left out.
        let below: Vec<_> = list
            .paths
            .iter()
            .map(|p| p.strip_prefix(&db).unwrap().to_path_buf())
            .collect();
        let expected: Vec<std::path::PathBuf> = ["@1@0@.JPG", "@2@0@.jpg", "b.@4@0@.jpeg", "b/@3@0@.png"]
            .iter()
            .map(Into::into)
            .collect();
        assert_eq!(below, expected);
        assert_eq!(
            list.positions().unwrap(),
            ndarray::array![[1.0, 0.0], [2.0, 0.0], [4.0, 0.0], [3.0, 0.0]]
        );

        // A bad name found in a directory names the directory and the path.
        std::fs::write(db.join("b/oops.jpg"), b"").unwrap();
        let e = image_paths(&db).unwrap().positions().unwrap_err().to_string();
        assert!(
            e.starts_with(&format!(
                "{}: image name '{}' has fewer",
                db.display(),
                db.join("b/oops.jpg").display()
            )),
            "{e}"
        );

        // DIR_images_paths.txt next to the directory gives the order instead.
        std::fs::write(tmp.path().join("database_images_paths.txt"), "b/@3@0@.png\n@2@0@.jpg\n").unwrap();
        let list = image_paths(&db).unwrap();
        assert_eq!(list.paths, vec![db.join("b/@3@0@.png"), db.join("@2@0@.jpg")]);
        assert_eq!(list.positions().unwrap(), ndarray::array![[3.0, 0.0], [2.0, 0.0]]);
        // A trailing '/' on the directory finds the same file.
        let slash = format!("{}/", db.display());
        assert_eq!(image_paths(&slash).unwrap().paths.len(), 2);

        let empty = tmp.path().join("empty");
        std::fs::create_dir(&empty).unwrap();
        let e = image_paths(&empty).unwrap_err().to_string();
        assert!(
            e.ends_with("contains no images (files ending in .jpg, .jpeg or .png, any case, at any depth)"),
            "{e}"
        );
        let e = image_paths(tmp.path().join("missing")).unwrap_err();
        assert!(
            matches!(
                e,
                Error::Io {
                    kind: std::io::ErrorKind::NotFound,
                    ..
                }
            ),
            "{e}"
        );
    }

    #[cfg(feature = "npy")]
    #[test]
    fn text_files_list_one_path_per_line() {
        let tmp = tempfile::tempdir().unwrap();
        let file = tmp.path().join("q.txt");
        // CRLF and LF endings; the last line without one.
        std::fs::write(&file, "a/@1@2@.jpg\r\n@3@4@.jpg\n/x/@-5.5@6@.png").unwrap();
        let list = image_paths(&file).unwrap();
        assert_eq!(list.paths.len(), 3);
        assert_eq!(
            list.positions().unwrap(),
            ndarray::array![[1.0, 2.0], [3.0, 4.0], [-5.5, 6.0]]
        );
        // One trailing newline ends the last line; it is not an empty line.
        std::fs::write(&file, "@1@2@.jpg\n").unwrap();
        assert_eq!(image_paths(&file).unwrap().paths.len(), 1);
        let message = |text: &[u8]| {
            std::fs::write(&file, text).unwrap();
            let e = image_paths(&file).and_then(|l| l.positions()).unwrap_err().to_string();
            e.strip_prefix(&format!("{} ", file.display())).unwrap().to_string()
        };
        assert_eq!(
            message(b"@1@2@.jpg\n\n@3@4@.jpg\n"),
            "line 2 is empty; every line must be an image path (one per descriptor row)"
        );
        assert_eq!(
            message(b"@1@2@.jpg\n\n"),
            "line 2 is empty; every line must be an image path (one per descriptor row)"
        );
        assert_eq!(message(b""), "is empty; it must list one image path per line");
        assert_eq!(message(b"@1@2@.jpg\n@\xff@2@.jpg\n"), "line 2 is not valid UTF-8");
        assert_eq!(
            message(b"@1@2@.jpg\n@3@4@.jpg\nq/@5@north@.jpg\n"),
            "line 3: image name 'q/@5@north@.jpg' has utm_north 'north', which is not a number; \
             names must look like @utm_east@utm_north@...@.jpg"
        );
    }
}
