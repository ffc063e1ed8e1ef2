use image::imageops;
use unshear::{Config, Unshear};
fn main() {
    let a: Vec<String> = std::env::args().collect();
    let k: f64 = a[2].parse().unwrap();
    let img = image::open(&a[1]).unwrap();
    let shear = unshear::Shear::about_middle(k, img.height());
    let img = unshear::warp::apply_shear(&img, shear, unshear::warp::Interpolation::Linear, unshear::warp::Canvas::Same).0.to_luma8();
    let u = Unshear::new(Config::default()).unwrap();
    for s in [1u32, 2] {
        let im = imageops::resize(&img, img.width() * s, img.height() * s, imageops::FilterType::Triangle);
        let r = u.estimate_gray(&im);
        println!("x{s}: k {:?}", r.k);
        for f in &r.faces { println!("   box {:?} k {:?} meas {:.3} conf {:.2} score {:?} roll {:.1}", f.face_box, f.k, f.k_measured, f.confidence, f.face_score, f.roll_degrees); }
    }
}
