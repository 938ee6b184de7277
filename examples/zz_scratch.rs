use std::time::Instant;
use structid::lti::{LinearSystem, Signal};
use structid::{GaussianKernel, Kernel};
fn main() {
    let len = 4000;
    let z = Signal::from_fn(len, 1, |k, _| ((k * 7919) % 4000) as f64 / 2000.0 - 1.0);
    let k = GaussianKernel::new(0.2).unwrap();
    let mut g = vec![0.0; len * len];
    for _ in 0..3 {
        let t = Instant::now();
        k.fill_gram_columns(&z, 0..len, &mut g);
        println!("gram fill {:.3}", t.elapsed().as_secs_f64());
    }
    let sys = structid::lti::testing::random_stable_system(42, 4, 1, 1, 0.9);
    let gm = faer::MatRef::from_column_major_slice(&g, len, len);
    let mut q = faer::Mat::<f64>::zeros(len, len);
    let mut m = faer::Mat::<f64>::zeros(len, len);
    for _ in 0..3 {
        let t = Instant::now();
        sys.apply_columns(gm, q.as_mut(), faer::Accum::Replace, 1.0);
        let t1 = t.elapsed().as_secs_f64();
        let t = Instant::now();
        sys.apply_columns(q.transpose(), m.as_mut(), faer::Accum::Replace, 1.0);
        println!("apply cols {:.3}, transposed {:.3}", t1, t.elapsed().as_secs_f64());
    }
    let t = Instant::now();
    let mut s = 0.0; for v in g.iter_mut() { *v = (-*v).exp(); s += *v; }
    println!("plain exp 16M {:.3} {s}", t.elapsed().as_secs_f64());
}
