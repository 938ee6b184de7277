//! The benchmark loaders on the real files: sample counts, split boundaries and lengths, mean
//! removal, first and last values against the raw lines, sample times. Outside CI the tests
//! skip with a message when the files are absent; under CI (`CI` set) they fail. The data
//! directory is `$STRUCTID_DATA` or `../shared/data` beside the workspace.

use std::path::Path;

use structid_io::{CascadedTanks, Silverbox, SilverboxSplit, TanksSplit};

mod common;

/// The data rows of a benchmark CSV, parsed with plain string handling: one vector of fields
/// per non-empty line after the header (a trailing comma gives an empty last field).
fn raw_rows(path: &Path) -> Vec<Vec<Option<f64>>> {
    let text = std::fs::read_to_string(path).unwrap();
    text.lines()
        .skip(1)
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            l.split(',')
                .map(|f| {
                    let f = f.trim();
                    (!f.is_empty()).then(|| f.parse::<f64>().unwrap())
                })
                .collect()
        })
        .collect()
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}

#[test]
fn silverbox_splits_against_the_raw_file() {
    let Some(path) = common::silverbox_file() else {
        return;
    };
    let sb = Silverbox::load(&path).unwrap();
    assert_eq!(sb.u.len(), 131072);
    assert_eq!(sb.y.len(), 131072);
    assert_eq!(sb.sample_time, 16384.0 / 1e7);
    assert!(mean(&sb.u).abs() < 1e-12, "{}", mean(&sb.u));
    assert!(mean(&sb.y).abs() < 1e-12, "{}", mean(&sb.y));

    let rows = raw_rows(&path);
    assert_eq!(rows.len(), 131072);
    let raw_u: Vec<f64> = rows.iter().map(|r| r[0].unwrap()).collect();
    let raw_y: Vec<f64> = rows.iter().map(|r| r[1].unwrap()).collect();
    assert!(rows.iter().all(|r| r.len() == 3 && r[2].is_none()));
    let (mu, my) = (mean(&raw_u), mean(&raw_y));
    assert!((sb.means.0 - mu).abs() < 1e-15 && (sb.means.1 - my).abs() < 1e-15);
    // The file's first line of data, as text.
    assert_eq!((raw_u[0], raw_y[0]), (0.0057756, 0.0093978));

    let expected = [
        (SilverboxSplit::Estimation, 40650, 105712, 65062, 0),
        (SilverboxSplit::TestArrowFull, 100, 40575, 40475, 50),
        (
            SilverboxSplit::TestArrowNoExtrapolation,
            100,
            32100,
            32000,
            50,
        ),
        (SilverboxSplit::TestMultisine, 105712, 127400, 21688, 50),
    ];
    for (split, start, end, len, settle) in expected {
        let r = sb.split(split);
        assert_eq!(r.range, start..end, "{split}");
        assert_eq!((r.u.len(), r.y.len()), (len, len), "{split}");
        assert_eq!(r.settle, settle, "{split}");
        assert_eq!(r.sample_time, sb.sample_time);
        assert_eq!(r.name, format!("silverbox-{split}"));
        let close = |a: f64, b: f64| (a - b).abs() < 1e-15;
        assert!(close(r.u[0], raw_u[start] - mu), "{split}: first u");
        assert!(close(r.y[0], raw_y[start] - my), "{split}: first y");
        assert!(close(r.u[len - 1], raw_u[end - 1] - mu), "{split}: last u");
        assert!(close(r.y[len - 1], raw_y[end - 1] - my), "{split}: last y");
        // Scoring a zero simulation gives the RMS of y after the settling samples.
        let rms = r.scored_rms(&vec![0.0; len]).unwrap();
        let direct =
            (r.y[settle..].iter().map(|v| v * v).sum::<f64>() / (len - settle) as f64).sqrt();
        assert!((rms - direct).abs() <= 1e-15 * direct.max(1.0));
        assert_eq!(r.data().unwrap().len(), len);
    }
    // The no-extrapolation test is the start of the full arrow test.
    let full = sb.split(SilverboxSplit::TestArrowFull);
    let part = sb.split(SilverboxSplit::TestArrowNoExtrapolation);
    assert_eq!(part.u[..], full.u[..32000]);
}

#[test]
fn cascaded_tanks_records_against_the_raw_file() {
    let Some(path) = common::tanks_file() else {
        return;
    };
    let tanks = CascadedTanks::load(&path).unwrap();
    let rows = raw_rows(&path);
    assert_eq!(rows.len(), 1024);
    // Columns uEst, uVal, yEst, yVal, Ts; Ts only on the first row.
    assert_eq!(rows[0][4], Some(4.0));
    assert!(rows[1..].iter().all(|r| r[4].is_none()));
    for (split, cu, cy) in [(TanksSplit::Estimation, 0, 2), (TanksSplit::Test, 1, 3)] {
        let r = tanks.split(split);
        assert_eq!((r.u.len(), r.y.len()), (1024, 1024), "{split}");
        assert_eq!(r.range, 0..1024);
        assert_eq!(r.settle, 0);
        assert_eq!(r.sample_time, 4.0);
        assert_eq!(r.name, format!("cascaded-tanks-{split}"));
        for k in [0, 1, 1023] {
            assert_eq!(r.u[k], rows[k][cu].unwrap(), "{split} u[{k}]");
            assert_eq!(r.y[k], rows[k][cy].unwrap(), "{split} y[{k}]");
        }
        // No mean is removed.
        assert!(mean(&r.y) > 1.0);
    }
    assert_eq!(tanks.estimation.u[0], 3.2567);
    assert_eq!(tanks.test.y[0], 4.9728);
}

#[test]
fn each_loader_rejects_the_other_file() {
    let (Some(sb), Some(tanks)) = (common::silverbox_file(), common::tanks_file()) else {
        return;
    };
    let e = Silverbox::load(&tanks).unwrap_err().to_string();
    assert!(
        e.contains("line 1") && e.contains("expected the header V1,V2"),
        "{e}"
    );
    let e = CascadedTanks::load(&sb).unwrap_err().to_string();
    assert!(
        e.contains("line 1") && e.contains("uEst,uVal,yEst,yVal,Ts"),
        "{e}"
    );
}
