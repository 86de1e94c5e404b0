//! Largest differences between the curves of two table files built on the same grid (e.g.
//! before and after a solver change): `cargo run -p fem-core --release --example lut_diff --
//! OLD.lut NEW.lut`. Prints per curve the largest |delta| of u_s, a, P and the inner volume
//! over the common steps, then the overall maxima.

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [old, new] = args.as_slice() else {
        return Err("usage: lut_diff OLD.lut NEW.lut".into());
    };
    let old = fem_core::lut::read_lut(std::path::Path::new(old))?;
    let new = fem_core::lut::read_lut(std::path::Path::new(new))?;
    if old.lut.grid != new.lut.grid {
        return Err("the tables have different grids".into());
    }
    let mut overall = [0.0f64; 4];
    for entry in &old.lut.curves {
        let index = entry.index;
        let (Some(a), Some(b)) = (old.lut.curve(index), new.lut.curve(index)) else {
            println!("curve {index}: missing in one table");
            continue;
        };
        let mut max = [0.0f64; 4];
        for k in 0..a.len().min(b.len()) {
            let d = [
                a.u_s_mm[k] - b.u_s_mm[k],
                a.a_mm[k] - b.a_mm[k],
                a.load_n[k] - b.load_n[k],
                a.volume_mm3[k] - b.volume_mm3[k],
            ];
            for (m, x) in max.iter_mut().zip(d) {
                *m = m.max(x.abs());
            }
        }
        for (o, m) in overall.iter_mut().zip(max) {
            *o = o.max(m);
        }
        println!(
            "curve {index:3} ({}): {} vs {} points; max |delta| u_s {:.1e} mm, a {:.1e} mm, P \
             {:.1e} N, volume {:.1e} mm3",
            old.lut.grid.describe(index),
            a.len(),
            b.len(),
            max[0],
            max[1],
            max[2],
            max[3]
        );
    }
    println!(
        "all curves: max |delta| u_s {:.1e} mm, a {:.1e} mm, P {:.1e} N, volume {:.1e} mm3",
        overall[0], overall[1], overall[2], overall[3]
    );
    Ok(())
}
