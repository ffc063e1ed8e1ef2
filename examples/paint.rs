//! Temporary: writes an image with its annotated faces painted over.
use unshear::dev::dataset::{CaltechWebFaces, FaceDataset};
fn main() {
    let a: Vec<String> = std::env::args().collect();
    let faces = CaltechWebFaces::new(&a[1]).faces().unwrap();
    for name in &a[3..] {
        let mine: Vec<_> = faces.iter().filter(|f| f.image.ends_with(name)).collect();
        let img = image::open(&mine[0].image).unwrap();
        unshear::dev::eval::shear::face_free(&img, &mine).save(format!("{}/{name}.png", a[2])).unwrap();
    }
}
