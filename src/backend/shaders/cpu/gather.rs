//! The CPU twin of `shaders_wgsl/gather.wgsl` and `shaders_glsl/vulkan/gather.comp`
//! (preparing a step, the last stage): an array put into sorted order, element k of the result
//! being element `order[k]` of the input. The GPU backends gather the sort's second key word,
//! then the particles, their lo parts and radius attribute; the CPU preparation
//! (`GpuStepData::prepare`, their reference) gathers with this very function.

use rayon::prelude::*;

/// `out[k] = src[order[k]]`.
pub fn gather<T: Copy + Send + Sync>(src: &[T], order: &[u32]) -> Vec<T> {
    order.par_iter().map(|&i| src[i as usize]).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gather_takes_each_element_from_where_the_order_says() {
        assert_eq!(
            gather(&[10, 11, 12, 13], &[2, 0, 3, 1]),
            vec![12, 10, 13, 11]
        );
        assert_eq!(gather::<u32>(&[], &[]), Vec::<u32>::new());
    }
}
