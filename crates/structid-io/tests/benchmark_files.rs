//! The official benchmark CSV files read as they are. Outside CI the tests skip with a message
//! when `../shared/data` is absent; under CI (the `CI` variable set) they fail.

use structid_io::DataTable;

mod common;
use common::benchmark_file as shared_data;

#[test]
fn silverbox_csv_with_quoted_header_and_trailing_commas() {
    let Some(path) = shared_data("silverbox/SNLS80mV.csv") else {
        return;
    };
    let t = DataTable::read(&path).unwrap();
    assert_eq!(t.names, ["V1", "V2"]);
    assert_eq!(t.len(), 131072);
    let s = t.select(&["V1", "V2"]).unwrap();
    assert_eq!(s.sample(0), &[0.0057756, 0.0093978]);
}

#[test]
fn cascaded_tanks_csv_with_a_sparse_column() {
    let Some(path) = shared_data("cascaded_tanks/dataBenchmark.csv") else {
        return;
    };
    let t = DataTable::read(&path).unwrap();
    assert_eq!(t.names, ["uEst", "uVal", "yEst", "yVal", "Ts"]);
    assert_eq!(t.len(), 1024);
    let s = t.select(&["uEst", "yEst"]).unwrap();
    assert_eq!(s.len(), 1024);
    // Ts holds a single value; selecting it names the first empty line.
    let e = t.select(&["Ts"]).unwrap_err().to_string();
    assert!(e.contains("line 3") && e.contains("`Ts`"), "{e}");
}
