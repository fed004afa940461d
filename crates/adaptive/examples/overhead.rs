//! The overhead tables of `filtrace bench adaptive` without the CLI:
//! `cargo run -p filtrace-adaptive --example overhead -- [width height repeats]`.

fn main() {
    let a: Vec<usize> = std::env::args().skip(1).filter_map(|s| s.parse().ok()).collect();
    let mut cfg = filtrace_adaptive::bench::BenchConfig::paper();
    if let [w, h, rest @ ..] = a.as_slice() {
        (cfg.width, cfg.height) = (*w, *h);
        if let Some(r) = rest.first() {
            cfg.repeats = *r;
        }
    }
    match filtrace_adaptive::bench::run(&cfg) {
        Ok(r) => print!("{}", r.to_markdown()),
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(1);
        }
    }
}
