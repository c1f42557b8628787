"""PyG's machinery on the library's models, shared by their tests:
``torch.compile`` (graph breaks counted by ``torch._dynamo.explain``, one
graph for batches of every size, outputs equal to eager) and
``torch.autocast`` (bfloat16 on the CPU: logits close to float32, finite
gradients)."""
import torch

MAX_GRAPH_BREAKS = 3


def check_compiles(model, batches, backend='inductor', rtol=1e-4):
    explanation = torch._dynamo.explain(model)(batches[0])
    assert explanation.graph_break_count <= MAX_GRAPH_BREAKS, \
        [str(reason.reason)[:200] for reason in explanation.break_reasons]
    torch._dynamo.reset()
    compiled = torch.compile(model, dynamic=True, backend=backend)
    model.eval()
    with torch.no_grad():
        compiled(batches[0])
        # batches of other sizes run the same graph
        with torch._dynamo.config.patch(error_on_recompile=True):
            for batch in batches:
                eager, traced = model(batch), compiled(batch)
                scale = eager.abs().max()
                assert (traced - eager).abs().max() <= rtol * scale
    torch._dynamo.reset()


def check_autocast(model, batch, tolerance=0.05):
    """Logits under bfloat16 autocast within ``tolerance`` (relative to the
    largest logit) of float32; a training step gives finite gradients."""
    model.eval()
    with torch.no_grad():
        full = model(batch)
        with torch.autocast('cpu', dtype=torch.bfloat16):
            mixed = model(batch)
    assert (mixed.float() - full).abs().max() <= tolerance * \
        full.abs().max()
    model.train()
    with torch.autocast('cpu', dtype=torch.bfloat16):
        loss = model(batch).float().square().mean()
    loss.backward()
    grads = [p.grad for p in model.parameters() if p.grad is not None]
    assert grads and all(bool(torch.isfinite(g).all()) for g in grads)
