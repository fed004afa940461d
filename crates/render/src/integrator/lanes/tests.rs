use super::*;
use filtrace_core::Vec3;

#[test]
fn compress_store_packs_the_kept_lanes_in_order() {
    let v: [f32; LANES] = std::array::from_fn(|i| i as f32 + 0.5);
    let w: [u32; LANES] = std::array::from_fn(|i| 100 + i as u32);
    #[cfg(target_arch = "x86_64")]
    let avx2 = filtrace_core::cpu::isa().has_avx2();
    #[cfg(not(target_arch = "x86_64"))]
    let avx2 = false;
    for keep in 0..=255u8 {
        let kept: Vec<usize> = (0..LANES).filter(|&i| (keep >> i) & 1 == 1).collect();
        let mut dst = [-1.0f32; 11];
        compress_store(F8::<false>::from_array(v), keep, &mut dst, 3);
        let mut dst_u = [0u32; 9];
        compress_store_u32(U8::<false>::from_array(w), keep, &mut dst_u, 1);
        for (j, &i) in kept.iter().enumerate() {
            assert_eq!((dst[3 + j], dst_u[1 + j]), (v[i], w[i]), "mask {keep:#010b}");
        }
        assert_eq!(dst[..3], [-1.0; 3]);
        if avx2 {
            let mut a = [-1.0f32; 11];
            compress_store(F8::<true>::from_array(v), keep, &mut a, 3);
            assert_eq!(a, dst);
        }
    }
}

#[test]
fn vector_helpers_match_glam() {
    let v: Vec<Vec3> =
        (0..LANES).map(|i| Vec3::new(0.3 + i as f32, -1.7 * i as f32, 1.0 / (1.0 + i as f32))).collect();
    let mut a = V8::<false>::default();
    for (i, x) in v.iter().enumerate() {
        a.set_lane(i, *x);
    }
    let n = a.normalize();
    let d = a.dot(n);
    for (i, x) in v.iter().enumerate() {
        assert_eq!(n.lane(i), x.normalize());
        assert_eq!(d.lane(i), x.dot(x.normalize()));
        assert_eq!(a.max_element().lane(i), x.max_element());
    }
}

#[test]
fn columns_transpose_rows() {
    let table: Vec<f32> = (0..200).map(|k| k as f32 * 0.5 - 7.0).collect();
    let start = [0usize, 17, 3, 192, 64, 65, 100, 8];
    let portable = columns::<false>(&table, &start).unwrap();
    for (j, c) in portable.iter().enumerate() {
        for (i, &s) in start.iter().enumerate() {
            assert_eq!(c.lane(i), table[s + j]);
        }
    }
    assert!(columns::<false>(&table, &[193; LANES]).is_none());
    assert!(columns::<false>(&table, &[usize::MAX; LANES]).is_none());
    #[cfg(target_arch = "x86_64")]
    if filtrace_core::cpu::isa().has_avx2() {
        let v = columns::<true>(&table, &start).unwrap();
        for j in 0..8 {
            assert_eq!(v[j].to_array(), portable[j].to_array());
        }
    }
}

#[test]
fn alias_pick8_matches_alias_table_sample() {
    use filtrace_core::sampling::AliasTable;
    let weights = [3.0f32, 0.0, 1.5, 7.25, 0.5, 2.0, 0.0, 9.0];
    for n in 1..=8usize {
        let table = AliasTable::new(&weights[..n]);
        let (mut q, mut alias, mut pmf) = ([0.0f32; LANES], [0u32; LANES], [0.0f32; LANES]);
        for i in 0..n {
            let (qi, ai) = table.bin(i).unwrap();
            (q[i], alias[i], pmf[i]) = (qi, if n == 1 { 0 } else { ai }, table.pmf(i));
        }
        for step in 0..64u32 {
            let u: [f32; LANES] = std::array::from_fn(|i| ((step * 8 + i as u32) as f32 * 0.618_034).fract());
            let (k, pm) = alias_pick8::<false>(F8::from_array(u), n as u32, &q, &alias, &pmf);
            #[cfg(target_arch = "x86_64")]
            if filtrace_core::cpu::isa().has_avx2() {
                let (k2, pm2) = alias_pick8::<true>(F8::from_array(u), n as u32, &q, &alias, &pmf);
                assert_eq!((k2.to_array(), pm2.to_array()), (k.to_array(), pm.to_array()));
            }
            for (i, &ui) in u.iter().enumerate() {
                let (ks, ps) = table.sample(ui);
                assert_eq!(
                    (k.to_array()[i] as usize, pm.lane(i).to_bits()),
                    (ks, ps.to_bits()),
                    "n {n} u {ui}"
                );
            }
        }
    }
}

/// `lookup` / `lookup_u32` read `table[idx]` for tables of eight entries (`vpermps`) and
/// of any other length (`vgatherdps`), portable and AVX2 alike.
#[test]
fn lookups_read_the_indexed_entries_for_any_table_length() {
    for len in [1usize, 3, 8, 9, 117] {
        let f: Vec<f32> = (0..len).map(|k| k as f32 * 1.25 - 3.0).collect();
        let w: Vec<u32> = (0..len).map(|k| (k as u32).wrapping_mul(2_654_435_761)).collect();
        let idx: [u32; LANES] = std::array::from_fn(|i| ((i * 37 + 5) % len) as u32);
        let (a, b) = (lookup::<false>(&f, U8::from_array(idx)), lookup_u32::<false>(&w, U8::from_array(idx)));
        for i in 0..LANES {
            assert_eq!((a.lane(i), b.to_array()[i]), (f[idx[i] as usize], w[idx[i] as usize]), "len {len}");
        }
        #[cfg(target_arch = "x86_64")]
        if filtrace_core::cpu::isa().has_avx2() {
            let a2 = lookup::<true>(&f, U8::from_array(idx));
            let b2 = lookup_u32::<true>(&w, U8::from_array(idx));
            assert_eq!((a2.to_array(), b2.to_array()), (a.to_array(), b.to_array()), "len {len}");
        }
    }
}
