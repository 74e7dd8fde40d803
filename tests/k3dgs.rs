//! K-3DGS's building blocks against their references: tensor forward kinematics against the
//! foundation's.

use burn::tensor::{Device, Tensor, TensorData};
use selfmodel::tensor_kinematics::TensorChain;

#[test]
fn tensor_forward_kinematics_matches_the_foundations_for_every_link() {
    let dev = Device::flex();
    let chain = selfmodel::arm4::chain();
    let tc = TensorChain::new(&chain);
    let qs: Vec<Vec<f64>> = (0..5)
        .map(|i| (0..4).map(|k| ((i * 7 + k * 3) % 11) as f64 * 0.37 - 1.8).collect())
        .collect();
    let flat: Vec<f32> = qs.iter().flatten().map(|&v| v as f32).collect();
    let q = Tensor::<2>::from_data(TensorData::new(flat, [5, 4]), &dev);
    let (r, t) = tc.link_frames(q);
    assert_eq!(r.dims(), [5, tc.links(), 3, 3]);
    let r = r.into_data().try_to_vec::<f32>().unwrap();
    let t = t.into_data().try_to_vec::<f32>().unwrap();
    for (b, q) in qs.iter().enumerate() {
        for (l, frame) in chain.link_frames(q).iter().enumerate() {
            let m = frame.rotation.to_rotation_matrix();
            for i in 0..3 {
                let tt = t[(b * tc.links() + l) * 3 + i] as f64;
                assert!((tt - frame.translation.vector[i]).abs() < 1e-5, "pose {b} link {l}");
                for j in 0..3 {
                    let rr = r[((b * tc.links() + l) * 3 + i) * 3 + j] as f64;
                    assert!((rr - m[(i, j)]).abs() < 1e-5, "pose {b} link {l} R[{i}][{j}]");
                }
            }
        }
    }
}
