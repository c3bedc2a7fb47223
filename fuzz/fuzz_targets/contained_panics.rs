//! vtkio is not hardened against hostile input and can panic; `aarbf::io::vtk` runs it inside
//! `catch_unwind` and turns such a panic into an error naming the file, so a user never sees
//! it. libfuzzer-sys's panic hook aborts before any unwinding, which would report that
//! contained panic as a crash and end the run. This hook lets panics raised inside vtkio
//! unwind to aarbf's `catch_unwind` (the regression test replays such inputs through the
//! real reader), and aborts, as libfuzzer-sys does, on every other panic: a panic in aarbf's
//! own code is still a finding.

pub fn contain_vtkio_panics() {
    let abort_hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let in_vtkio = info
            .location()
            .is_some_and(|l| l.file().contains("/vtkio-"));
        if !in_vtkio {
            abort_hook(info);
        }
    }));
}
