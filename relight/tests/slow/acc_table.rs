//! The near-field coupling table (`AccTable`) against numerical
//! integration of eq. 8 at its nodes.

use ltm_relight::nearfield::AccTable;
use ltm_testkit::haar::{amplitude, integrate};

#[test]
fn table_nodes_match_numerical_integration_of_eq_8() {
    let limits = ltm_codec::Limits::default();
    let cells = 16;
    let table = AccTable::new(32, cells, &limits).unwrap();
    let samples = 1 << 16;
    let mut looked_up = Vec::new();
    let mut checked = 0;
    // Nodes sit at cell centres; a lookup at a node's (s, o) reads it.
    // The rows are at log₂ w = log₂(1/128) + (q + ½)/16 and b₀ on a grid
    // of min(w, 1)/16: probe every fifth row at every seventh b₀.
    for q in (0..128).step_by(5) {
        let w = (-7.0 + (q as f64 + 0.5) / 16.0).exp2();
        let step = w.min(1.0) / cells as f64;
        let widest = (-7.0 + (q as f64 + 1.0) / 16.0).exp2();
        for r in (0..((1.0 + widest) / step) as usize).step_by(7) {
            let b0 = -widest + (r as f64 + 0.5) * step;
            let (s, o) = (1.0 / w, b0 / -w);
            for i in [0usize, 1] {
                looked_up.clear();
                table.couplings_where(i, s, o, |_| true, &mut looked_up);
                let mut dense = [0.0f64; 32];
                looked_up.iter().for_each(|&(k, d)| dense[k as usize] = d);
                for (k, &d) in dense.iter().enumerate() {
                    let numeric = integrate(i, k, s, o, samples);
                    // The midpoint rule's bound plus the values' f32 rounding.
                    let bound = 6.0 * amplitude(i) * amplitude(k) / samples as f64 + 1e-6;
                    assert!(
                        (d - numeric).abs() <= bound,
                        "node ({q}, {r}): D_{i},{k}({s}, {o}) = {d}, numerically {numeric}"
                    );
                    checked += 1;
                }
            }
        }
    }
    assert!(checked > 5000, "{checked}");
}
