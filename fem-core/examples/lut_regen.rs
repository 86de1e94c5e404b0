//! Re-solve curves of a LUT file and print the largest difference of every column from the
//! stored values: `cargo run -p fem-core --release --example lut_regen -- FILE [INDEX...]`
//! (default: the first, middle and last successful curves).

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let path = args.next().ok_or("usage: lut_regen FILE [INDEX...]")?;
    let file = fem_core::lut::read_lut(std::path::Path::new(&path))?;
    let lut = &file.lut;
    let mut indices: Vec<usize> = args.map(|a| a.parse()).collect::<Result<_, _>>()?;
    if indices.is_empty() {
        let ok: Vec<usize> = lut
            .curves
            .iter()
            .filter(|c| c.failure.is_none())
            .map(|c| c.index)
            .collect();
        indices = vec![ok[0], ok[ok.len() / 2], ok[ok.len() - 1]];
    }
    for index in indices {
        let params = lut.grid.curve_params(index);
        let stored = lut.curve(index).ok_or("no such curve")?;
        let curve = fem_core::solve_curve(&params)?;
        let mut max = [0.0f64; 5];
        let mut worst_a = (0, 0.0, 0.0);
        for (k, p) in curve.points.iter().enumerate().take(stored.len()) {
            let d = [
                p.h_mm - stored.h_mm[k],
                p.u_s_mm - stored.u_s_mm[k],
                p.a_mm - stored.a_mm[k],
                p.load_n - stored.load_n[k],
                p.volume_mm3 - stored.volume_mm3[k],
            ];
            for (m, x) in max.iter_mut().zip(d) {
                *m = m.max(x.abs());
            }
            if d[2].abs() >= worst_a.1 {
                worst_a = (k, d[2].abs(), p.a_mm);
            }
        }
        println!(
            "curve {index} ({}): {} points ({} stored), {:.2} s; max |diff| h {:.1e} u_s {:.1e} \
             a {:.1e} (step {}, a = {:.5}) P {:.1e} volume {:.1e}",
            lut.grid.describe(index),
            curve.points.len(),
            stored.len(),
            curve.solve_seconds,
            max[0],
            max[1],
            max[2],
            worst_a.0,
            worst_a.2,
            max[3],
            max[4]
        );
    }
    Ok(())
}
