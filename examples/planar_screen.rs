//! The object screen's verdicts on the ground-truth suite's clouds as users post them
//! (camera frame): every case the screen finds planar, and how many it refuses as a bare
//! plane. `cargo run --release --example planar_screen -- FIRST_SET SETS` (sets of 180
//! cases, 10000 apart). The fit screens the same clouds after setting stray points
//! aside, so a verdict here can differ from the fit's on a cloud with outliers.
use supertoroid::bench::synthetic::{Presentation, category, presented};
use supertoroid::fit::planarity::{Planarity, planarity};
use supertoroid::suite::ground_truth::make_case;

fn main() {
    let args: Vec<u64> = std::env::args()
        .skip(1)
        .map(|s| s.parse().expect("FIRST_SET SETS"))
        .collect();
    let [first, sets] = args[..] else {
        panic!("usage: planar_screen FIRST_SET SETS");
    };
    let mut refused = 0;
    for set in (first..first + sets * 10000).step_by(10000) {
        for seed in set..set + 180 {
            let (partial, noise, outliers) = category((seed % 1000) as usize % 180);
            let case = make_case(seed, partial, noise, outliers);
            let (points, _, _) = presented(&case, Presentation::Camera);
            let verdict = planarity(&points, seed);
            if !matches!(verdict, Planarity::Solid) {
                let view = if partial { "view" } else { "full" };
                println!("{seed} {view} noise {noise} outliers {outliers}: {verdict:?}");
            }
            refused += usize::from(matches!(verdict, Planarity::BarePlane { .. }));
        }
    }
    println!("{refused} of {} cases refused as a bare plane", sets * 180);
}
