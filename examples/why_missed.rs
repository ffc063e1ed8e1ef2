//! Temporary: why the network detector misses a face.
use unshear::detect::boxes::{box_around_eyes, EYE_DISTANCE_PER_BOX_WIDTH};
use unshear::detect::{ProposalNet, ProposalParams};
use unshear::{Config, FaceStart, Point, Unshear};

fn main() {
    let a: Vec<String> = std::env::args().collect();
    let img = image::open(&a[1]).unwrap();
    let v: Vec<f64> = a[2..7].iter().map(|s| s.parse().unwrap()).collect();
    let (mut re, mut le) = (Point::new(v[0], v[1]), Point::new(v[2], v[3]));
    let shear = unshear::Shear::about_middle(v[4], img.height());
    let (img, pl) = unshear::warp::apply_shear(&img, shear, unshear::warp::Interpolation::Linear, unshear::warp::Canvas::Expand);
    re = pl.from_frame(shear.apply(re));
    le = pl.from_frame(shear.apply(le));
    let u = Unshear::new(Config::default()).unwrap();
    let gray = Unshear::gray(&img);
    let net = ProposalNet::embedded().unwrap();
    let ps = net.propose(
        &gray,
        &ProposalParams { min_eye_distance: 15.0, min_logit: -8.0, max_proposals: 500, ..Default::default() },
    );
    let mid = re.midpoint(le);
    let ed = re.distance(le);
    let mut near: Vec<_> = ps
        .iter()
        .enumerate()
        .filter(|(_, p)| p.eyes_midpoint.distance(mid) < 0.5 * ed && (p.eye_distance / ed).ln().abs() < 0.4)
        .collect();
    near.sort_by(|a, b| b.1.logit.total_cmp(&a.1.logit));
    let above0 = ps.iter().filter(|p| p.logit >= 0.0).count();
    println!("{} proposals >= 0 in image; near ones (rank, logit, off/ed, scale):", above0);
    for (i, p) in near.iter().take(4) {
        println!("  #{i} {:.2} {:.2} {:.2}", p.logit, p.eyes_midpoint.distance(mid) / ed, p.eye_distance / ed);
        let w = p.eye_distance / EYE_DISTANCE_PER_BOX_WIDTH;
        let r = u.estimate_face(&gray, box_around_eyes(p.eyes_midpoint, w, w, 0.0), FaceStart::default());
        if let Some(r) = r { println!("    score {:?} k {:?} conf {:.2}", r.face_score, r.k, r.confidence); } else { println!("    none"); }
        for k0 in [-0.3, 0.3] {
            let r = u.estimate_face(&gray, box_around_eyes(p.eyes_midpoint, w, w, 0.0), FaceStart { k: k0, ..FaceStart::default() });
            if let Some(r) = r { println!("    start {k0}: score {:?} k {:?} conf {:.2}", r.face_score, r.k, r.confidence); }
        }
    }
    let roll = (le.y - re.y).atan2(le.x - re.x);
    let w = ed / EYE_DISTANCE_PER_BOX_WIDTH;
    let r = u.estimate_face(&gray, box_around_eyes(mid, w, w, 0.0), FaceStart::default());
    println!("true box (roll {:.1} deg): {:?}", roll.to_degrees(), r.map(|r| (r.face_score, r.k, r.confidence)));
}
