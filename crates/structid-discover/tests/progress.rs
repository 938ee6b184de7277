//! A discovery tells its progress observer about every candidate location it identifies.

use std::sync::{Arc, Mutex};

use structid_core::progress::Progress;
use structid_discover::discover::{DiscoverSettings, discover};
use structid_discover::hypotheses::Nominal;
use structid_testcases::synthetic;

#[test]
fn discovery_reports_each_location() {
    let c = synthetic::generate(synthetic::CaseKind::Static, 0);
    let n = Nominal::from_polynomial(&c.nominal).unwrap();
    let heard = Arc::new(Mutex::new(Vec::new()));
    let h = Arc::clone(&heard);
    let settings = DiscoverSettings::default().with_progress(Progress::new(move |done, total| {
        h.lock().unwrap().push((done, total))
    }));
    discover(&n, &c.estimation, &c.validation, &settings).unwrap();
    let heard = heard.lock().unwrap();
    let locations = n.locations().len() as u64;
    // The locations in order, once each (a second pass around a refitted G counts again).
    let first: Vec<(u64, Option<u64>)> = (1..=locations).map(|i| (i, Some(locations))).collect();
    assert!(heard.len() >= first.len(), "{heard:?}");
    assert_eq!(heard[..first.len()], first[..]);
}
