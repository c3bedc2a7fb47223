#!/usr/bin/env python3
"""The alpha-beta model of distributed rendering (docs/distributed.md, "Model"), for P ranks.

Geometry: N particles uniform in a cube of side L, split by the k-d tree into P bricks of side
L_b = L P^(-1/3) (p = P^(1/3) a side); each particle's support is h (the render's radius, a
fraction of the domain's diagonal). A particle is a ghost in every other brick its support
meets, so along each axis it is one more brick's ghost when it lies within h of an internal
face: the mean ghost factor over all bricks is (1 + 2h(p-1)/L)^3 and an interior brick's
(every face internal, the one that bounds memory) is (1 + 2h/L_b)^3.

Compositing (W x H pixels, [r, g, b, T] in f64, 32 bytes a pixel, 64^2 tiles): direct send
moves each rank's footprint, about the image's share of one brick's silhouette, c P^(-2/3) of
it (c = sqrt(3), a cube seen along its diagonal), to the tiles' owners in one all-to-all-v;
binary swap (radix-k with k = 2) moves half of what a rank holds in each of log2 P rounds,
W H 32 (1 - 1/P) bytes in all. Time = alpha messages + beta bytes; alpha and beta are
arguments (the defaults are an HDR InfiniBand link: 1.5 us, 12.5 GB/s).

Run: python3 scripts/dist_model.py [--radius 0.01] [--particles 1e8] [--attributes 3]
     [--size 1024] [--alpha 1.5e-6] [--bandwidth 12.5e9]
"""

import argparse
import math


def ghost_factors(P, h_over_L):
    p = P ** (1.0 / 3.0)
    mean = (1.0 + 2.0 * h_over_L * (p - 1.0)) ** 3
    interior = (1.0 + 2.0 * h_over_L * p) ** 3 if P > 1 else 1.0
    return mean, interior


def direct_send(P, W, H, alpha, beta, c=math.sqrt(3.0)):
    pixel = 32
    tiles = math.ceil(W / 64) * math.ceil(H / 64)
    footprint = min(1.0, c * P ** (-2.0 / 3.0)) if P > 1 else 1.0
    sent = W * H * pixel * footprint
    messages = min(P - 1, max(1, math.ceil(tiles * footprint))) if P > 1 else 0
    return sent, messages, alpha * messages + beta * sent


def binary_swap(P, W, H, alpha, beta):
    pixel = 32
    rounds = math.ceil(math.log2(P)) if P > 1 else 0
    sent = W * H * pixel * (1.0 - 1.0 / P)
    return sent, rounds, alpha * rounds + beta * sent


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--radius", type=float, default=0.01, help="support, share of the diagonal")
    ap.add_argument("--particles", type=float, default=1e8)
    ap.add_argument("--attributes", type=int, default=3, help="f64 attributes a particle")
    ap.add_argument("--size", type=int, default=1024, help="image side in pixels")
    ap.add_argument("--alpha", type=float, default=1.5e-6, help="latency a message, s")
    ap.add_argument("--bandwidth", type=float, default=12.5e9, help="bytes/s")
    a = ap.parse_args()
    h_over_L = a.radius * math.sqrt(3.0)
    beta = 1.0 / a.bandwidth
    W = H = a.size
    particle_bytes = 24 + 8 * a.attributes
    print(
        f"radius {a.radius:.3g} of the diagonal (h = {h_over_L:.4f} L), "
        f"{a.particles:.3g} particles of {particle_bytes} B, {W}x{H}, "
        f"alpha {a.alpha * 1e6:.2g} us, {a.bandwidth / 1e9:.3g} GB/s"
    )
    print()
    print(
        "| P | ghosts, mean | ghosts, interior brick | particles a rank (MB) | "
        "direct send: MB, msgs, ms | binary swap: MB, msgs, ms | gather to rank 0 (ms) |"
    )
    print("|---|---|---|---|---|---|---|")
    for k in range(3, 13):
        P = 2**k
        mean, interior = ghost_factors(P, h_over_L)
        per_rank = a.particles / P * interior * particle_bytes / 1e6
        ds_bytes, ds_msgs, ds_t = direct_send(P, W, H, a.alpha, beta)
        bs_bytes, bs_msgs, bs_t = binary_swap(P, W, H, a.alpha, beta)
        gather = beta * W * H * 32 + a.alpha * math.ceil(math.log2(P))
        print(
            f"| {P} | {100 * (mean - 1):.1f}% | {100 * (interior - 1):.1f}% | {per_rank:.1f} | "
            f"{ds_bytes / 1e6:.2f}, {ds_msgs}, {ds_t * 1e3:.2f} | "
            f"{bs_bytes / 1e6:.1f}, {bs_msgs}, {bs_t * 1e3:.2f} | {gather * 1e3:.2f} |"
        )


if __name__ == "__main__":
    main()
