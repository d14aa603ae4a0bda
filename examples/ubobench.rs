use std::borrow::Cow;
use std::time::Instant;
fn main() {
    let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
    let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions::default())).unwrap();
    println!("push {} ", adapter.limits().max_immediate_size);
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        label: None, required_features: wgpu::Features::empty(), required_limits: adapter.limits(),
        experimental_features: wgpu::ExperimentalFeatures::disabled(), memory_hints: wgpu::MemoryHints::Performance, trace: wgpu::Trace::Off })).unwrap();
    let n = 262144u32;
    let out = device.create_buffer(&wgpu::BufferDescriptor { label: None, size: n as u64 * 16, usage: wgpu::BufferUsages::STORAGE, mapped_at_creation: false });
    let ubo = device.create_buffer(&wgpu::BufferDescriptor { label: None, size: 1024, usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::STORAGE, mapped_at_creation: false });
    let src = |decl: &str, load: &str| format!("
@group(0) @binding(0) var<storage, read_write> out: array<vec4<f32>>;
{decl}
@compute @workgroup_size(64) fn main(@builtin(global_invocation_id) id: vec3<u32>) {{
    let d = vec4<f32>(f32(id.x));
    var acc = vec4<f32>(0.0);
    acc += d * {load}(0u); acc += d * {load}(1u); acc += d * {load}(2u); acc += d * {load}(3u);
    acc += d * {load}(4u); acc += d * {load}(5u); acc += d * {load}(6u); acc += d * {load}(7u);
    acc += d * {load}(8u); acc += d * {load}(9u); acc += d * {load}(10u); acc += d * {load}(11u);
    out[id.x] = acc;
}}");
    let variants = [
        ("ubo_vec4", src("@group(0) @binding(1) var<uniform> u: array<vec4<f32>, 16>; fn ld(k: u32) -> vec4<f32> { return u[k]; }", "ld")),
        ("ubo_struct", src("struct T { a: vec3<f32>, m: u32 } @group(0) @binding(1) var<uniform> u: array<T, 16>; fn ld(k: u32) -> vec4<f32> { return vec4<f32>(u[k].a, 1.0); }", "ld")),
        ("ssbo_vec4", src("@group(0) @binding(1) var<storage, read> u: array<vec4<f32>>; fn ld(k: u32) -> vec4<f32> { return u[k]; }", "ld")),
        ("ssbo_fixed", src("@group(0) @binding(1) var<storage, read> u: array<vec4<f32>, 16>; fn ld(k: u32) -> vec4<f32> { return u[k]; }", "ld")),
        ("ubo_cond", src("struct T { a: vec3<f32>, m: u32 } @group(0) @binding(1) var<uniform> u: array<T, 16>; var<private> ig: u32; fn ld(k: u32) -> vec4<f32> { if k == ig { return vec4<f32>(0.0); } return vec4<f32>(u[k].a, 1.0); }", "ld").replace("let d = vec4<f32>(f32(id.x));", "let d = vec4<f32>(f32(id.x)); ig = id.x & 15u;")),
        ("ssbo_cond", src("struct T { a: vec3<f32>, m: u32 } @group(0) @binding(1) var<storage, read> u: array<T, 16>; var<private> ig: u32; fn ld(k: u32) -> vec4<f32> { if k == ig { return vec4<f32>(0.0); } return vec4<f32>(u[k].a, 1.0); }", "ld").replace("let d = vec4<f32>(f32(id.x));", "let d = vec4<f32>(f32(id.x)); ig = id.x & 15u;")),
        ("ubo_loopidx", src("@group(0) @binding(1) var<uniform> u: array<vec4<f32>, 16>; fn ld(k: u32) -> vec4<f32> { var a = vec4<f32>(0.0); for (var i = 0u; i < 1u; i++) { a += u[k + i]; } return a; }", "ld")),
        ("ubo_cond_hoist", src("struct T { a: vec3<f32>, m: u32 } @group(0) @binding(1) var<uniform> u: array<T, 16>; var<private> ig: u32; fn ld(k: u32) -> vec4<f32> { let a = u[k].a; if k == ig { return vec4<f32>(0.0); } return vec4<f32>(a, 1.0); }", "ld").replace("let d = vec4<f32>(f32(id.x));", "let d = vec4<f32>(f32(id.x)); ig = id.x & 15u;")),
        ("ubo_select", src("struct T { a: vec3<f32>, m: u32 } @group(0) @binding(1) var<uniform> u: array<T, 16>; var<private> ig: u32; fn ld(k: u32) -> vec4<f32> { let a = u[k].a; return select(vec4<f32>(a, 1.0), vec4<f32>(0.0), k == ig); }", "ld").replace("let d = vec4<f32>(f32(id.x));", "let d = vec4<f32>(f32(id.x)); ig = id.x & 15u;")),
        ("alu", src("fn ld(k: u32) -> vec4<f32> { return vec4<f32>(f32(k)); }", "ld")),
    ];
    for (name, s) in variants {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor { label: None, source: wgpu::ShaderSource::Wgsl(Cow::Owned(s.clone())) });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor { label: None, layout: None, module: &module, entry_point: Some("main"), compilation_options: Default::default(), cache: None });
        let mut entries = vec![wgpu::BindGroupEntry { binding: 0, resource: out.as_entire_binding() }];
        if s.contains("binding(1)") { entries.push(wgpu::BindGroupEntry { binding: 1, resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding { buffer: &ubo, offset: 0, size: std::num::NonZeroU64::new(256) }) }); }
        let bg = device.create_bind_group(&wgpu::BindGroupDescriptor { label: None, layout: &pipeline.get_bind_group_layout(0), entries: &entries });
        let run = |reps: u32| {
            let mut enc = device.create_command_encoder(&Default::default());
            { let mut pass = enc.begin_compute_pass(&Default::default());
              pass.set_pipeline(&pipeline); pass.set_bind_group(0, &bg, &[]);
              for _ in 0..reps { pass.dispatch_workgroups(n / 64, 1, 1); } }
            queue.submit([enc.finish()]);
            device.poll(wgpu::PollType::wait_indefinitely()).unwrap();
        };
        run(1);
        let mut best = f64::MAX;
        for _ in 0..3 { let t = Instant::now(); run(20); best = best.min(t.elapsed().as_secs_f64() / 20.0); }
        println!("{name:12} {:8.2} ms/dispatch  {:6.2} ns/invocation", best * 1e3, best * 1e9 / n as f64);
    }
}
