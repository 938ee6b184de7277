//! End-to-end tests of `structid data`: benchmark splits (when the official files are present;
//! see `common::benchmark_data`) and the general CSV selection, which needs no data files.

use std::path::Path;

mod common;
use common::benchmark_data::{silverbox_file, tanks_file};
use common::*;

/// Header and data rows of a written CSV file.
fn read_csv(path: &Path) -> (String, Vec<String>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines().map(str::to_string);
    let header = lines.next().unwrap();
    (header, lines.collect())
}

#[test]
fn silverbox_split_has_the_expected_rows() {
    let Some(file) = silverbox_file() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("est.csv");
    let o = ok(&[
        "data",
        "silverbox",
        "--file",
        p(&file),
        "--split",
        "estimation",
        "--out",
        p(&out),
    ]);
    assert!(
        o.stdout
            .contains("silverbox-estimation: 65062 samples (file rows 40650..105712")
            && o.stdout.contains("sample time 0.0016384 s")
            && o.stdout.contains("scored from sample 0"),
        "{}",
        o.stdout
    );
    assert_eq!(o.stdout.lines().count(), 1, "{}", o.stdout);
    let (header, rows) = read_csv(&out);
    assert_eq!(header, "u,y");
    assert_eq!(rows.len(), 65062);
    // The written file reads back as identification data.
    let t = structid_io::DataTable::read(&out).unwrap();
    assert_eq!(t.select(&["u", "y"]).unwrap().len(), 65062);

    // Every split into a directory.
    let all = dir.path().join("all");
    let o = ok(&[
        "data",
        "silverbox",
        "--file",
        p(&file),
        "--split",
        "all",
        "--out",
        p(&all),
    ]);
    assert_eq!(o.stdout.lines().count(), 4, "{}", o.stdout);
    for (name, len) in [
        ("estimation", 65062),
        ("test-arrow-full", 40475),
        ("test-arrow-no-extrapolation", 32000),
        ("test-multisine", 21688),
    ] {
        assert_eq!(
            read_csv(&all.join(format!("{name}.csv"))).1.len(),
            len,
            "{name}"
        );
    }
    assert!(o.stdout.contains("scored from sample 50"), "{}", o.stdout);
}

#[test]
fn tanks_splits() {
    let Some(file) = tanks_file() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("val.csv");
    let o = ok(&[
        "data",
        "tanks",
        "--file",
        p(&file),
        "--split",
        "test",
        "--out",
        p(&out),
    ]);
    assert!(
        o.stdout.contains("1024 samples") && o.stdout.contains("sample time 4 s"),
        "{}",
        o.stdout
    );
    let (header, rows) = read_csv(&out);
    assert_eq!(header, "u,y");
    assert_eq!(rows.len(), 1024);
    assert_eq!(rows[0], "0.97619,4.9728");
    let all = dir.path().join("all");
    ok(&[
        "data",
        "tanks",
        "--file",
        p(&file),
        "--split",
        "all",
        "--out",
        p(&all),
    ]);
    assert_eq!(read_csv(&all.join("estimation.csv")).1[0], "3.2567,5.205");
    assert_eq!(read_csv(&all.join("test.csv")).1.len(), 1024);
}

#[test]
fn bad_split_name_lists_the_valid_ones() {
    let e = input_error(&[
        "data",
        "silverbox",
        "--file",
        "SNLS80mV.csv",
        "--split",
        "validation",
        "--out",
        "x.csv",
    ]);
    assert!(
        e.contains("unknown Silverbox split `validation`")
            && e.contains(
                "estimation, test-arrow-full, test-arrow-no-extrapolation, test-multisine, all"
            ),
        "{e}"
    );
    let e = input_error(&[
        "data",
        "tanks",
        "--file",
        "dataBenchmark.csv",
        "--split",
        "val",
        "--out",
        "x.csv",
    ]);
    assert!(e.contains("valid splits: estimation, test, all"), "{e}");
}

#[test]
fn missing_benchmark_file_is_an_input_error() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("SNLS80mV.csv");
    let out = dir.path().join("est.csv");
    let e = input_error(&[
        "data",
        "silverbox",
        "--file",
        p(&missing),
        "--split",
        "estimation",
        "--out",
        p(&out),
    ]);
    assert!(
        e.contains("Silverbox benchmark file was not found at") && e.contains(p(&missing)),
        "{e}"
    );
    assert!(!out.exists());
}

#[test]
fn refuses_to_overwrite_the_input() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in.csv");
    std::fs::write(&input, "u,y\n1,2\n3,4\n").unwrap();
    let same = dir.path().join("sub/../in.csv");
    std::fs::create_dir(dir.path().join("sub")).unwrap();
    let e = input_error(&["data", "csv", "--file", p(&input), "--out", p(&same)]);
    assert!(e.contains("refusing to write"), "{e}");
    // Before the file is read: a benchmark command refuses too, even on a file that is not one.
    let e = input_error(&[
        "data",
        "silverbox",
        "--file",
        p(&input),
        "--split",
        "estimation",
        "--out",
        p(&input),
    ]);
    assert!(e.contains("refusing to write"), "{e}");
    let e = input_error(&[
        "data",
        "tanks",
        "--file",
        p(&input),
        "--split",
        "all",
        "--out",
        p(&input),
    ]);
    assert!(e.contains("refusing to write"), "{e}");
    assert_eq!(std::fs::read_to_string(&input).unwrap(), "u,y\n1,2\n3,4\n");
}

#[test]
fn csv_selects_renames_cuts_and_centres() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("log.txt");
    std::fs::write(&input, "logger v2\n1;10;a\n2;20;b\n3;30;c\n6;40;d\n").unwrap();
    let out = dir.path().join("out.csv");
    let o = ok(&[
        "data",
        "csv",
        "--file",
        p(&input),
        "--no-header",
        "--skip-rows",
        "1",
        "--delimiter",
        ";",
        "--columns",
        "#1,#0",
        "--names",
        "u,y",
        "--range",
        "1..3",
        "--remove-mean",
        "--out",
        p(&out),
    ]);
    assert!(
        o.stdout.contains("2 samples (rows 1..3 of 4 data rows)")
            && o.stdout.contains("means removed: u 25, y 3"),
        "{}",
        o.stdout
    );
    assert_eq!(
        std::fs::read_to_string(&out).unwrap(),
        "u,y\n-5.0,-1.0\n5.0,0.0\n"
    );

    // By header name, with a trailing comma and a sparse unused column (like the tanks file).
    let input = dir.path().join("tanks_like.csv");
    std::fs::write(&input, "\"uEst\",\"yEst\",\"Ts\",\n1.5,2.5,4,\n3.5,4.5,,\n").unwrap();
    ok(&[
        "data",
        "csv",
        "--file",
        p(&input),
        "--columns",
        "yEst,uEst",
        "--names",
        "y,u",
        "--out",
        p(&out),
    ]);
    assert_eq!(
        std::fs::read_to_string(&out).unwrap(),
        "y,u\n2.5,1.5\n4.5,3.5\n"
    );
    // Selecting the sparse column, or all columns, names the line of the gap.
    let e = input_error(&[
        "data",
        "csv",
        "--file",
        p(&input),
        "--columns",
        "Ts",
        "--out",
        p(&out),
    ]);
    assert!(
        e.contains("line 3") && e.contains("`Ts`") && e.contains("empty"),
        "{e}"
    );
    let e = input_error(&["data", "csv", "--file", p(&input), "--out", p(&out)]);
    assert!(e.contains("line 3") && e.contains("`Ts`"), "{e}");
    // A missing column, a bad number, a bad range.
    let e = input_error(&[
        "data",
        "csv",
        "--file",
        p(&input),
        "--columns",
        "uVal",
        "--out",
        p(&out),
    ]);
    assert!(
        e.contains("no column `uVal`; available columns: `uEst`, `yEst`, `Ts`"),
        "{e}"
    );
    std::fs::write(&input, "u,y\n1,2\n3,x\n").unwrap();
    let e = input_error(&["data", "csv", "--file", p(&input), "--out", p(&out)]);
    assert!(e.contains("line 3, column `y`: cannot parse `x`"), "{e}");
    std::fs::write(&input, "u,y\n1,2\n3,4\n").unwrap();
    let e = input_error(&[
        "data",
        "csv",
        "--file",
        p(&input),
        "--range",
        "1..5",
        "--out",
        p(&out),
    ]);
    assert!(e.contains("--range") && e.contains("2 data rows"), "{e}");
    let e = input_error(&[
        "data",
        "csv",
        "--file",
        p(&input),
        "--columns",
        "#x",
        "--out",
        p(&out),
    ]);
    assert!(e.contains("--columns") && e.contains("`#x`"), "{e}");
}
