/* S by columns (core/csr.c): for every column, the rows its index lists are the rows of the public
 * view that hold it, in increasing order; and one row summed alone (sdi_csrb_eval, as edits do) is
 * the bytes the level build wrote for it, for positions and attributes. */
#include "test.h"
#include "../../core/internal.h"

static int index_matches(sd_complex *c, int L)
{
    for (int l = 0; l < L; l++) {
        sd_csr v;
        if (sd_complex_matrix(c, l, &v, NULL))
            return 0;
        const sd_csrb *S = &c->lv[l]->S;
        uint32_t *cnt = calloc(v.ncols + 1, sizeof *cnt), *rows = malloc((v.rowptr[v.nrows] + 1) * sizeof *rows);
        for (uint32_t e = 0; e < v.rowptr[v.nrows]; e++)
            cnt[v.col[e] + 1]++;
        for (uint32_t j = 0; j < v.ncols; j++)
            cnt[j + 1] += cnt[j];
        for (uint32_t r = 0; r < v.nrows; r++)
            for (uint32_t e = v.rowptr[r]; e < v.rowptr[r + 1]; e++)
                rows[cnt[v.col[e]]++] = r;
        int ok = 1;
        for (uint32_t j = 0, at = 0; ok && j < v.ncols; j++) {
            sdi_users u = sdi_csrb_users(S, j);
            for (uint32_t r; ok && sdi_users_next(&u, &r);)
                ok = at < cnt[j] && rows[at++] == r;
            ok = ok && at == cnt[j];
        }
        sdi_rowpos at = {UINT32_MAX, 0}; /* rows in order for channel 1, from checkpoints else */
        for (uint32_t r = 0; ok && r < S->nrows; r++)
            for (int ch = 0; ok && ch < c->lv[l]->nch; ch++) {
                int nc = c->lv[l]->ch[ch].ncomp;
                double x[16];
                sdi_csrb_eval(S, r, c->lv[l]->ch[ch].data, NULL, NULL, nc, x, ch ? &at : NULL);
                ok = !memcmp(x, c->lv[l + 1]->ch[ch].data + (size_t)r * nc, nc * sizeof *x);
            }
        free(cnt);
        free(rows);
        if (!ok)
            return 0;
    }
    return 1;
}

TEST(csr_columns_and_rows)
{
    for (int sh = 0; sh < 4; sh++) {
        mesh m = {0};
        sd_options o = {0};
        if (sh == 0)
            shape_cube_tets(&m, 3);
        else if (sh == 1)
            shape_icosahedron(&m); /* edge rings kept as the opposite vertices (eopp) */
        else if (sh == 2)
            shape_mixed(&m);
        else {
            shape_three_fins(&m);
            o.nonmanifold_surface = SD_NMSURF_YING_ZORIN; /* flattened rows */
        }
        double *a = malloc(5 * m.nv * sizeof *a);
        for (size_t i = 0; i < 5 * m.nv; i++)
            a[i] = sin(0.7 * (double)i);
        sd_complex *c = mesh_complex(&m, &o, NULL);
        CHECK(c && sd_complex_add_channel(c, a, 5, NULL) == 1 && sd_complex_level(c, 3, NULL));
        CHECK(index_matches(c, 3));
        sd_complex_free(c);
        free(a);
        mesh_free(&m);
    }
}
