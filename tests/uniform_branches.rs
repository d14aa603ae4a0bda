//! No kernel branches on uniform values alone. Lavapipe (Mesa 22.3) specialises a kernel on the
//! uniform values that alone decide a branch (an `if`, a loop's exit, a switch) and rebuilds the
//! specialised kernel at every dispatch: that cost up to 30 ms a dispatch, whatever its size
//! (shaders/lib/bindings.wesl). Such a branch is decided by an override, a `select`, or a value
//! that also depends on something no compiler knows (a binding's length, a path's state).
//!
//! The check reads each composed kernel with naga. An expression is constant (literals,
//! constants, overrides), uniform (it reads a uniform binding at a fixed place and otherwise only
//! constants) or varying (anything else: function arguments, storage, call results). A local
//! variable assigned once takes its value's class; one assigned more than once is varying, as
//! its SSA value then merges control flow. WGSL's `a && b` and `a || b` branch on `a` (naga
//! lowers them so), which the check sees as the `if` it is. It looks within each function only:
//! a branch on an argument that callers pass from a uniform is not caught.

use std::collections::HashMap;

use gatetrace::gpu::kernels::KERNEL_SOURCES;
use naga::{AddressSpace, Block, Expression, Function, Handle, Module, Statement};

#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
enum Class {
    Constant,
    Uniform,
    Varying,
}

struct Classifier<'a> {
    module: &'a Module,
    function: &'a Function,
    locals: HashMap<Handle<naga::LocalVariable>, Class>,
}

impl Classifier<'_> {
    /// The class of the value `e` (of a pointer: of the value it points to).
    fn class(&self, e: Handle<Expression>) -> Class {
        let all = |hs: &mut dyn Iterator<Item = Handle<Expression>>| {
            hs.map(|h| self.class(h)).max().unwrap_or(Class::Constant)
        };
        match &self.function.expressions[e] {
            Expression::Literal(_) | Expression::Constant(_) | Expression::Override(_) | Expression::ZeroValue(_) => {
                Class::Constant
            }
            Expression::GlobalVariable(g) => match self.module.global_variables[*g].space {
                AddressSpace::Uniform => Class::Uniform,
                _ => Class::Varying,
            },
            Expression::LocalVariable(l) => self.locals.get(l).copied().unwrap_or(Class::Varying),
            Expression::Load { pointer } => self.class(*pointer),
            // A uniform read at a place that depends on anything but constants is not at a fixed
            // offset.
            Expression::Access { base, index } => match self.class(*index) {
                Class::Constant => self.class(*base),
                _ => Class::Varying,
            },
            Expression::AccessIndex { base, .. } => self.class(*base),
            Expression::Splat { value, .. } => self.class(*value),
            Expression::Swizzle { vector, .. } => self.class(*vector),
            Expression::Unary { expr, .. } => self.class(*expr),
            Expression::As { expr, .. } => self.class(*expr),
            Expression::Relational { argument, .. } => self.class(*argument),
            Expression::Binary { left, right, .. } => all(&mut [*left, *right].into_iter()),
            Expression::Select { condition, accept, reject } => all(&mut [*condition, *accept, *reject].into_iter()),
            Expression::Compose { components, .. } => all(&mut components.iter().copied()),
            Expression::Math { arg, arg1, arg2, arg3, .. } => {
                all(&mut [Some(*arg), *arg1, *arg2, *arg3].into_iter().flatten())
            }
            _ => Class::Varying,
        }
    }

    /// The local variable a pointer expression points into, if any.
    fn local_root(&self, mut e: Handle<Expression>) -> Option<Handle<naga::LocalVariable>> {
        loop {
            match &self.function.expressions[e] {
                Expression::LocalVariable(l) => return Some(*l),
                Expression::Access { base, .. } | Expression::AccessIndex { base, .. } => e = *base,
                _ => return None,
            }
        }
    }
}

/// Every assignment to each local variable in `block`: (variable, value or None for a write this
/// check cannot see, such as a pointer passed to a function).
fn assignments(
    c: &Classifier,
    block: &Block,
    out: &mut Vec<(Handle<naga::LocalVariable>, Option<Handle<Expression>>)>,
) {
    for statement in block.iter() {
        match statement {
            Statement::Store { pointer, value } => {
                if let Some(l) = c.local_root(*pointer) {
                    // A store through an index or a member changes part of the variable: the
                    // variable's value then merges several stores.
                    let whole = matches!(c.function.expressions[*pointer], Expression::LocalVariable(_));
                    out.push((l, whole.then_some(*value)));
                }
            }
            Statement::Call { arguments, .. } => {
                for a in arguments {
                    if let Some(l) = c.local_root(*a) {
                        out.push((l, None));
                    }
                }
            }
            Statement::Block(b) => assignments(c, b, out),
            Statement::If { accept, reject, .. } => {
                assignments(c, accept, out);
                assignments(c, reject, out);
            }
            Statement::Switch { cases, .. } => cases.iter().for_each(|case| assignments(c, &case.body, out)),
            Statement::Loop { body, continuing, .. } => {
                assignments(c, body, out);
                assignments(c, continuing, out);
            }
            _ => {}
        }
    }
}

/// The branches in `block` whose condition is uniform: (kind of branch, condition).
fn uniform_branches(c: &Classifier, block: &Block, out: &mut Vec<(&'static str, Handle<Expression>)>) {
    let check = |what: &'static str, e: Handle<Expression>, out: &mut Vec<_>| {
        if c.class(e) == Class::Uniform {
            out.push((what, e));
        }
    };
    for statement in block.iter() {
        match statement {
            Statement::Block(b) => uniform_branches(c, b, out),
            Statement::If { condition, accept, reject } => {
                check("if", *condition, out);
                uniform_branches(c, accept, out);
                uniform_branches(c, reject, out);
            }
            Statement::Switch { selector, cases } => {
                check("switch", *selector, out);
                cases.iter().for_each(|case| uniform_branches(c, &case.body, out));
            }
            Statement::Loop { body, continuing, break_if } => {
                if let Some(b) = break_if {
                    check("break if", *b, out);
                }
                uniform_branches(c, body, out);
                uniform_branches(c, continuing, out);
            }
            _ => {}
        }
    }
}

/// The uniform branches of one function, each with its condition's source text.
fn function_findings(module: &Module, function: &Function, wgsl: &str) -> Vec<String> {
    let mut c = Classifier { module, function, locals: HashMap::new() };
    let mut stores = Vec::new();
    assignments(&c, &function.body, &mut stores);
    let mut values: HashMap<Handle<naga::LocalVariable>, Vec<Option<Handle<Expression>>>> = HashMap::new();
    for (l, local) in function.local_variables.iter() {
        values.entry(l).or_default().extend(local.init.map(Some));
    }
    for (l, v) in stores {
        values.entry(l).or_default().push(v);
    }
    // Classes of the locals assigned once, to a fixed point (a value may read another local).
    let single: Vec<_> = values
        .iter()
        .filter_map(|(l, v)| match v[..] {
            [Some(e)] => Some((*l, e)),
            _ => None,
        })
        .collect();
    for (l, _) in &single {
        c.locals.insert(*l, Class::Constant);
    }
    loop {
        let mut changed = false;
        for (l, e) in &single {
            let class = c.class(*e);
            if c.locals[l] != class {
                c.locals.insert(*l, class);
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
    let mut out = Vec::new();
    uniform_branches(&c, &function.body, &mut out);
    let name = function.name.clone().unwrap_or_default();
    out.into_iter()
        .map(|(what, e)| {
            let text = function.expressions.get_span(e).to_range().and_then(|r| wgsl.get(r)).unwrap_or("");
            format!("fn {name}: {what} `{text}`")
        })
        .collect()
}

#[test]
fn no_kernel_branches_on_uniform_values_alone() {
    let mut findings = Vec::new();
    for kernel in KERNEL_SOURCES {
        let module = naga::front::wgsl::parse_str(kernel.wgsl).unwrap_or_else(|e| panic!("{}: {e}", kernel.name));
        let functions = module.functions.iter().map(|(_, f)| f).chain(module.entry_points.iter().map(|e| &e.function));
        for function in functions {
            for f in function_findings(&module, function, kernel.wgsl) {
                findings.push(format!("{} ({:?}): {f}", kernel.name, kernel.feature));
            }
        }
    }
    findings.sort();
    findings.dedup();
    assert!(findings.is_empty(), "branches on uniform values alone:\n{}", findings.join("\n"));
}

#[test]
fn the_check_sees_a_branch_on_a_uniform() {
    // The patterns lavapipe specialised on, and the forms that replaced them.
    let wgsl = "
        struct P { n: u32, lens: f32 }
        @group(0) @binding(0) var<uniform> params: P;
        @group(0) @binding(1) var<storage, read> table: array<f32>;
        override THIN: bool = false;
        fn direct() -> u32 { if params.lens > 0.0 { return 1u; } return 0u; }
        fn through_let() -> u32 { let p = params; if p.n == 0u { return 1u; } return 0u; }
        fn short_circuit(x: f32) -> bool { return params.n == 0u || x < table[0]; }
        fn search(x: f32) -> u32 {
            var lo = 0u;
            var hi = params.n - 1u;
            while lo < hi { let mid = (lo + hi) / 2u; if table[mid] < x { lo = mid + 1u; } else { hi = mid; } }
            return lo;
        }
        fn fine(x: f32) -> f32 {
            var y = 0.0;
            if THIN { y = 1.0; }
            let n = min(params.n, arrayLength(&table));
            if n == 0u { y += 1.0; }
            if x < params.lens { y += 2.0; }
            return select(y, 3.0, params.n > 2u);
        }
        @compute @workgroup_size(1) fn main() {
            _ = direct(); _ = through_let(); _ = short_circuit(0.5); _ = search(0.5); _ = fine(0.5);
        }";
    let module = naga::front::wgsl::parse_str(wgsl).unwrap();
    let flagged: Vec<String> = module
        .functions
        .iter()
        .filter(|(_, f)| !function_findings(&module, f, wgsl).is_empty())
        .map(|(_, f)| f.name.clone().unwrap())
        .collect();
    assert_eq!(flagged, ["direct", "through_let", "short_circuit"], "the check must see these and pass `fine`");
}
